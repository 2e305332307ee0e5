//! A bounded reorder window: restores log-time order for messages that arrive
//! slightly out of order in file order, holding at most a time window and a
//! byte budget. Messages later than the window allows are passed on at once
//! (never dropped) and counted.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::InputMessage;

/// Min-heap entry ordered by (log time, arrival number) so ties keep file order.
struct Entry {
    key: (u64, u64),
    message: InputMessage,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.key.cmp(&other.key)
    }
}

pub(super) struct ReorderWindow {
    heap: BinaryHeap<Reverse<Entry>>,
    window_ns: u64,
    max_bytes: usize,
    held_bytes: usize,
    arrivals: u64,
    newest_log_time_ns: u64,
    last_released_ns: Option<u64>,
    /// Messages that arrived after a later message had already been released.
    pub(super) late: u64,
}

impl ReorderWindow {
    pub(super) fn new(window_ns: u64, max_bytes: usize) -> Self {
        Self {
            heap: BinaryHeap::new(),
            window_ns,
            max_bytes,
            held_bytes: 0,
            arrivals: 0,
            newest_log_time_ns: 0,
            last_released_ns: None,
            late: 0,
        }
    }

    /// Add a message; returns the messages now safe to release, in order.
    pub(super) fn push(&mut self, message: InputMessage, out: &mut Vec<InputMessage>) {
        if self
            .last_released_ns
            .is_some_and(|last| message.log_time_ns < last)
        {
            // Too late to put in order: pass it on now rather than lose it.
            self.late += 1;
            out.push(message);
            return;
        }
        self.newest_log_time_ns = self.newest_log_time_ns.max(message.log_time_ns);
        self.held_bytes += message.data.len();
        let key = (message.log_time_ns, self.arrivals);
        self.arrivals += 1;
        self.heap.push(Reverse(Entry { key, message }));
        while let Some(Reverse(oldest)) = self.heap.peek() {
            let expired = oldest.key.0.saturating_add(self.window_ns) < self.newest_log_time_ns;
            if !(expired || self.held_bytes > self.max_bytes) {
                break;
            }
            out.push(self.pop());
        }
    }

    /// Release everything still held, in order.
    pub(super) fn drain(&mut self, out: &mut Vec<InputMessage>) {
        while !self.heap.is_empty() {
            out.push(self.pop());
        }
    }

    fn pop(&mut self) -> InputMessage {
        let Reverse(entry) = self.heap.pop().expect("caller checked non-empty");
        self.held_bytes -= entry.message.data.len();
        self.last_released_ns = Some(entry.key.0);
        entry.message
    }

    #[cfg(test)]
    pub(super) fn held(&self) -> usize {
        self.heap.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(log_time_ns: u64, size: usize) -> InputMessage {
        InputMessage {
            channel_id: 1,
            sequence: 0,
            log_time_ns,
            publish_time_ns: log_time_ns,
            data: vec![0; size],
        }
    }

    fn run(window: &mut ReorderWindow, times: &[u64]) -> Vec<u64> {
        let mut out = Vec::new();
        for &t in times {
            window.push(msg(t, 1), &mut out);
        }
        window.drain(&mut out);
        out.iter().map(|m| m.log_time_ns).collect()
    }

    #[test]
    fn restores_order_within_the_window() {
        let mut window = ReorderWindow::new(10, usize::MAX);
        assert_eq!(
            run(&mut window, &[5, 3, 8, 4, 12, 9, 20]),
            vec![3, 4, 5, 8, 9, 12, 20]
        );
        assert_eq!(window.late, 0);
    }

    #[test]
    fn passes_on_and_counts_messages_later_than_the_window() {
        let mut window = ReorderWindow::new(10, usize::MAX);
        // 1 arrives after 30 pushed 5 out of the window and released it.
        let out = run(&mut window, &[5, 30, 1]);
        assert_eq!(out, vec![5, 1, 30]);
        assert_eq!(window.late, 1);
    }

    #[test]
    fn ties_keep_file_order() {
        let mut window = ReorderWindow::new(10, usize::MAX);
        let mut out = Vec::new();
        for seq in 0..5 {
            let mut m = msg(7, 1);
            m.sequence = seq;
            window.push(m, &mut out);
        }
        window.drain(&mut out);
        assert_eq!(
            out.iter().map(|m| m.sequence).collect::<Vec<_>>(),
            vec![0, 1, 2, 3, 4]
        );
    }

    #[test]
    fn byte_budget_bounds_what_is_held() {
        let mut window = ReorderWindow::new(u64::MAX / 2, 100);
        let mut out = Vec::new();
        for t in 0..1000 {
            window.push(msg(t, 30), &mut out);
            assert!(window.held() <= 4);
        }
    }
}
