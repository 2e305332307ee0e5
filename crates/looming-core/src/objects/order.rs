//! `f64` values as integers in `f64::total_cmp`'s order ([`key`]): the
//! selections of the objects stage (medians, percentiles, weighted medians
//! over thousands of cells) compare integers, one instruction, instead of
//! `total_cmp`'s two conversions per comparison. The same order, so the
//! same comparisons' verdicts, the same reordering and the same values.

/// `value`'s bits as an integer that orders as `f64::total_cmp` does
/// (negative values' magnitude bits flipped).
#[inline]
pub fn key(value: f64) -> i64 {
    let bits = value.to_bits() as i64;
    bits ^ (((bits >> 63) as u64) >> 1) as i64
}

/// The value of a [`key`] (the flip is its own inverse).
#[inline]
pub fn value(key: i64) -> f64 {
    f64::from_bits((key ^ (((key >> 63) as u64) >> 1) as i64) as u64)
}

/// The value at `index` in ascending order of the values whose keys
/// `keys` holds (`select_nth_unstable`); reorders `keys`.
pub fn select(keys: &mut [i64], index: usize) -> f64 {
    value(*keys.select_nth_unstable(index).1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Keys order as `total_cmp` does, and give the value back bit for bit.
    #[test]
    fn keys_order_as_total_cmp() {
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            5e-324,
            -5e-324,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
        ];
        let mut state = 17u64;
        for _ in 0..2000 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            values.push(f64::from_bits(state));
            values.push((state >> 11) as f64 / 1e12 - 4e3);
        }
        for a in &values {
            assert_eq!(value(key(*a)).to_bits(), a.to_bits());
            for b in values.iter().step_by(7) {
                assert_eq!(key(*a).cmp(&key(*b)), a.total_cmp(b), "{a} {b}");
            }
        }
    }
}
