//! Ids for our own schemas and channels that cannot collide with the input's.

use std::collections::BTreeSet;

/// Hands out ids above the largest one the input uses, then any free one below.
#[derive(Debug, Clone)]
pub struct IdAllocator {
    used: BTreeSet<u16>,
    lowest_valid: u16,
}

impl IdAllocator {
    /// `lowest_valid`: 1 for schemas (0 means "no schema"), 0 for channels.
    pub fn new(used: impl IntoIterator<Item = u16>, lowest_valid: u16) -> Self {
        Self {
            used: used.into_iter().collect(),
            lowest_valid,
        }
    }

    /// The next free id, or `None` when all 65536 are taken.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Option<u16> {
        let above_max = match self.used.last() {
            Some(&max) => max.checked_add(1),
            None => Some(self.lowest_valid),
        };
        let id = above_max
            .or_else(|| (self.lowest_valid..=u16::MAX).find(|id| !self.used.contains(id)))?;
        self.used.insert(id);
        Some(id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allocates_above_the_input_ids() {
        let mut ids = IdAllocator::new([1, 5, 3], 1);
        assert_eq!(ids.next(), Some(6));
        assert_eq!(ids.next(), Some(7));
    }

    #[test]
    fn starts_at_the_lowest_valid_id_for_an_empty_input() {
        assert_eq!(IdAllocator::new([], 1).next(), Some(1));
        assert_eq!(IdAllocator::new([], 0).next(), Some(0));
    }

    #[test]
    fn fills_gaps_when_the_top_is_taken() {
        let mut ids = IdAllocator::new([0, 2, u16::MAX], 0);
        assert_eq!(ids.next(), Some(1));
        assert_eq!(ids.next(), Some(3));
        let mut full = IdAllocator::new(0..=u16::MAX, 0);
        assert_eq!(full.next(), None);
    }
}
