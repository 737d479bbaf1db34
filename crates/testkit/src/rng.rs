//! Small deterministic pseudo-random generators for tests (no seed source, no dependency).

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

/// Marsaglia's xorshift64 followed by Vigna's multiplication (xorshift64*): the mutation
/// tests' generator, so that a seed picks the same corruptions in every test and fuzz
/// replay.
///
/// Each call shifts the state (`^= >> 12`, `^= << 25`, `^= >> 27`) and returns it times
/// `0x2545_f491_4f6c_dd1d`. The state must not start at 0 (it would stay 0).
///
/// ```
/// use voxreg_testkit::Xorshift;
///
/// let mut rng = Xorshift::new(0x9e37_79b9_7f4a_7c15);
/// assert_eq!(rng.next_u64(), 0x0d83_b3e2_9a21_487a);
/// assert!(rng.below(7) < 7);
/// ```
#[derive(Clone, Debug)]
pub struct Xorshift {
    state: u64,
}

impl Xorshift {
    /// A generator whose state starts at `seed` (not 0).
    pub fn new(seed: u64) -> Self {
        Xorshift { state: seed }
    }

    /// The next number (all 64 bits).
    pub fn next_u64(&mut self) -> u64 {
        self.state ^= self.state >> 12;
        self.state ^= self.state << 25;
        self.state ^= self.state >> 27;
        self.state.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// [`Xorshift::next_u64`] modulo `n`, in `[0, n)`; 0 when `n` is 0.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
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

    #[test]
    fn xorshift_keeps_the_mutation_tests_sequence() {
        // The outputs of the generator the reader and request mutation tests had inline.
        let mut rng = Xorshift::new(0x9e37_79b9_7f4a_7c15);
        let first: Vec<u64> = (0..4).map(|_| rng.next_u64()).collect();
        assert_eq!(
            first,
            [0x0d83_b3e2_9a21_487a, 0x54c4_4c79_f1fe_9d67, 0xa845_f342_007a_0e78, 0x7d6e_0b87_8a79_4779]
        );
        let below: Vec<usize> = (0..8).map(|i| rng.below([0, 1, 7, 1000][i % 4])).collect();
        assert_eq!(below, [0, 0, 2, 144, 0, 0, 4, 761]);
    }
}
