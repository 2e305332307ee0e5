//! A budget of bytes in flight between pipeline stages: the stage that
//! makes big items (the reader's copied input chunks) waits while the items
//! already made and not yet consumed hold more than the budget. The stage
//! queues bound the number of items; this bounds their bytes, which a
//! log's chunk size would otherwise set (32 queued chunks of 4 MiB in each
//! of two queues: 256 MiB).

use std::sync::{Arc, Condvar, Mutex, PoisonError};

/// Bytes in flight, shared by the stages.
#[derive(Debug)]
pub struct ByteBudget {
    limit_bytes: u64,
    in_flight_bytes: Mutex<u64>,
    freed: Condvar,
}

impl ByteBudget {
    pub fn new(limit_bytes: u64) -> Arc<Self> {
        Arc::new(Self {
            limit_bytes,
            in_flight_bytes: Mutex::new(0),
            freed: Condvar::new(),
        })
    }

    /// Wait until `bytes` more fit in the budget, or nothing is in flight
    /// (an item bigger than the budget still passes, alone), and count them
    /// until the ticket is dropped.
    pub fn acquire(self: &Arc<Self>, bytes: u64) -> Ticket {
        let mut in_flight = self
            .in_flight_bytes
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        while *in_flight > 0 && in_flight.saturating_add(bytes) > self.limit_bytes {
            in_flight = self
                .freed
                .wait(in_flight)
                .unwrap_or_else(PoisonError::into_inner);
        }
        *in_flight = in_flight.saturating_add(bytes);
        Ticket {
            budget: Arc::clone(self),
            bytes,
        }
    }

    fn release(&self, bytes: u64) {
        let mut in_flight = self
            .in_flight_bytes
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        *in_flight = in_flight.saturating_sub(bytes);
        self.freed.notify_all();
    }
}

/// Bytes counted in a [`ByteBudget`] until dropped: when the item it rides
/// with is consumed, or dropped unconsumed by a stage that stopped (so a
/// waiting stage never waits for bytes nobody will free).
#[derive(Debug)]
pub struct Ticket {
    budget: Arc<ByteBudget>,
    bytes: u64,
}

impl Drop for Ticket {
    fn drop(&mut self) {
        self.budget.release(self.bytes);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_producer_waits_until_tickets_are_dropped() {
        let budget = ByteBudget::new(10);
        let first = budget.acquire(6);
        let (tx, rx) = std::sync::mpsc::channel();
        let producer = {
            let budget = Arc::clone(&budget);
            std::thread::spawn(move || {
                let second = budget.acquire(6);
                tx.send(()).expect("the test waits");
                second
            })
        };
        assert!(
            rx.recv_timeout(Duration::from_millis(100)).is_err(),
            "12 bytes do not fit in 10"
        );
        drop(first);
        rx.recv_timeout(Duration::from_secs(10))
            .expect("room once the first ticket is dropped");
        drop(producer.join().expect("the producer finishes"));
        assert_eq!(*budget.in_flight_bytes.lock().expect("lock"), 0);
    }

    #[test]
    fn an_item_bigger_than_the_budget_passes_alone() {
        let budget = ByteBudget::new(10);
        let big = budget.acquire(50);
        assert_eq!(*budget.in_flight_bytes.lock().expect("lock"), 50);
        drop(big);
        assert_eq!(*budget.in_flight_bytes.lock().expect("lock"), 0);
    }
}
