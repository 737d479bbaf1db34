//! A small deterministic pseudo-random generator for tests (no seed source, no dependency).

use glam::DVec3;

/// Knuth's MMIX linear congruential generator: `state = state * a + c (mod 2^64)`.
///
/// Deterministic and tiny, which is all tests need: the same seed gives the same sequence
/// on every platform. Each call advances the state once and maps it to the output:
///
/// - [`Lcg::next_u32`]: the high 31 bits, `state >> 33`;
/// - [`Lcg::next_f64`]: the high 53 bits as a fraction, `(state >> 11) / 2^53`, in `[0, 1)`;
/// - [`Lcg::below`], [`Lcg::range`], [`Lcg::vec3`]: built on those two.
///
/// ```
/// use voxreg_testkit::Lcg;
///
/// let mut rng = Lcg::new(7);
/// let x = rng.range(-1.0, 1.0);
/// assert!((-1.0..1.0).contains(&x));
/// assert!(rng.below(6) < 6);
/// assert_eq!(Lcg::new(7).range(-1.0, 1.0), x);
/// ```
#[derive(Clone, Debug)]
pub struct Lcg {
    state: u64,
}

impl Lcg {
    /// The multiplier `a`.
    const A: u64 = 6364136223846793005;
    /// The increment `c`.
    const C: u64 = 1442695040888963407;

    /// A generator whose state starts at `seed`.
    pub fn new(seed: u64) -> Self {
        Lcg { state: seed }
    }

    /// Advances the state and returns it (all 64 bits; the low bits are weak).
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_mul(Self::A).wrapping_add(Self::C);
        self.state
    }

    /// The high 31 bits of the next state, in `[0, 2^31)`.
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 33) as u32
    }

    /// A uniform number in `[0, 1)`: the high 53 bits of the next state.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// [`Lcg::next_u32`] modulo `n` (`n > 0`), in `[0, n)`.
    pub fn below(&mut self, n: u32) -> u32 {
        self.next_u32() % n
    }

    /// A uniform number in `[lo, hi)`: `lo + (hi - lo) * next_f64()`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// A point with coordinates [`Lcg::range`]`(lo, hi)`, drawn x, then y, then z.
    pub fn vec3(&mut self, lo: f64, hi: f64) -> DVec3 {
        DVec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_are_views_of_one_state_sequence() {
        let mut state = 99u64;
        let mut rng = Lcg::new(99);
        for _ in 0..100 {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            assert_eq!(rng.clone().next_u64(), state);
            assert_eq!(rng.clone().next_u32(), (state >> 33) as u32);
            assert_eq!(rng.clone().next_f64(), (state >> 11) as f64 / (1u64 << 53) as f64);
            let x = rng.clone().range(-2.0, 14.0);
            assert_eq!(x, (state >> 11) as f64 / (1u64 << 53) as f64 * 16.0 - 2.0);
            rng.next_u64();
        }
    }

    #[test]
    fn ranges_hold() {
        let mut rng = Lcg::new(1);
        for _ in 0..1000 {
            assert!((0.0..1.0).contains(&rng.next_f64()));
            assert!(rng.below(7) < 7);
            let v = rng.vec3(-0.5, 0.5);
            assert!(v.abs().max_element() <= 0.5);
        }
    }
}
