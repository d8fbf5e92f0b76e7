//! Bit-exact emulation of the two random streams ManiSkill3 draws from at reset
//! (docs/env.md §9 "Exact emulation recipe", docs/tasks.md §0.3).
//!
//! * [`NumpyRandomState`] — numpy's legacy `np.random.RandomState(seed)`, used by the table
//!   scene for the robot's initial joint noise (`normal(0, σ, (1, n))`).
//! * [`TorchGenerator`] — torch's CPU generator as driven by `torch.manual_seed(seed)` and
//!   `torch.rand(...)` in float32, used for every object/goal placement.
//!
//! Both are plain 32-bit MT19937 ([`Mt19937`]) seeded with the classic `init_genrand`, so for
//! the same seed they produce the same `u32` sequence; they differ only in how the words are
//! turned into floats. Task code should derive placements with [`uniform_scaled`] so the
//! float32 operation order matches upstream.
//!
//! Caveat: [`NumpyRandomState::normal`] uses `f64::ln` / `f64::sqrt`; `sqrt` is correctly
//! rounded everywhere, `ln` comes from the platform libm (glibc on Linux, as numpy does), which
//! is what makes the Gaussian stream bit-identical to numpy's in practice.

use serde::{Deserialize, Serialize};

/// Number of 32-bit words in the MT19937 state.
const N: usize = 624;
/// MT19937 middle word offset.
const M: usize = 397;
/// MT19937 twist matrix constant.
const MATRIX_A: u32 = 0x9908_b0df;
/// Most significant bit mask.
const UPPER_MASK: u32 = 0x8000_0000;
/// Lower 31 bits mask.
const LOWER_MASK: u32 = 0x7fff_ffff;

/// The classic 32-bit Mersenne Twister (Matsumoto & Nishimura, `mt19937ar.c`).
///
/// Seeded with `init_genrand(seed mod 2³²)`:
/// `state[0] = seed`, `state[i] = 1812433253·(state[i−1] ⊕ (state[i−1] ≫ 30)) + i  (mod 2³²)`,
/// with the standard twist and tempering. This is exactly the engine behind numpy's legacy
/// `RandomState(int)` (`mt19937_seed`) and torch's CPU generator (`at::mt19937`, whose
/// `init_with_uint32` keeps `seed & 0xffffffff`). First output for seed 0: 2357136044; for
/// seed 5489 (the reference default): 3499211612.
///
/// The state serialises as `{"state": [624 words], "index": i}`; deserialisation rejects a
/// state of the wrong length or an out-of-range index.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "Mt19937Repr")]
pub struct Mt19937 {
    /// The 624-word state vector.
    state: Vec<u32>,
    /// Index of the next word to temper; `N` means "twist before the next output".
    index: usize,
}

/// Unchecked serde mirror of [`Mt19937`], validated by `TryFrom`.
#[derive(Deserialize)]
struct Mt19937Repr {
    state: Vec<u32>,
    index: usize,
}

impl TryFrom<Mt19937Repr> for Mt19937 {
    type Error = String;

    fn try_from(r: Mt19937Repr) -> Result<Self, Self::Error> {
        if r.state.len() != N {
            return Err(format!(
                "MT19937 state must have {N} words, got {}",
                r.state.len()
            ));
        }
        if r.index > N {
            return Err(format!("MT19937 index must be in 0..={N}, got {}", r.index));
        }
        let mt = Mt19937 {
            state: r.state,
            index: r.index,
        };
        if mt.is_degenerate() {
            return Err("MT19937 state is all zero (it would output zeros forever)".into());
        }
        Ok(mt)
    }
}

impl Mt19937 {
    /// Seeds with `init_genrand(seed mod 2³²)` (the seed is truncated to its low 32 bits, as
    /// both numpy's `mt19937_seed` and torch's `mt19937(uint64_t)` do).
    #[must_use]
    pub fn new(seed: u64) -> Self {
        let mut state = vec![0u32; N];
        state[0] = seed as u32;
        for i in 1..N {
            let prev = state[i - 1];
            state[i] = 1_812_433_253u32
                .wrapping_mul(prev ^ (prev >> 30))
                .wrapping_add(i as u32);
        }
        Mt19937 { state, index: N }
    }

    /// Whether the generator is in the all-zero state it never leaves (it then outputs 0
    /// forever): every word that still influences an output is zero. Only the upper bit of
    /// word 0 enters the next twist, and word 0 is output as a whole only at index 0.
    #[must_use]
    pub fn is_degenerate(&self) -> bool {
        self.state[1..].iter().all(|&w| w == 0)
            && self.state[0] & UPPER_MASK == 0
            && (self.index > 0 || self.state[0] == 0)
    }

    /// Regenerates all 624 words (the standard MT19937 twist).
    fn twist(&mut self) {
        let s = &mut self.state;
        for i in 0..N {
            let y = (s[i] & UPPER_MASK) | (s[(i + 1) % N] & LOWER_MASK);
            let mut v = s[(i + M) % N] ^ (y >> 1);
            if y & 1 != 0 {
                v ^= MATRIX_A;
            }
            s[i] = v;
        }
        self.index = 0;
    }

    /// Next tempered 32-bit output (`genrand_int32`). Allocation-free.
    pub fn next_u32(&mut self) -> u32 {
        if self.index >= N {
            self.twist();
        }
        let mut y = self.state[self.index];
        self.index += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^= y >> 18;
        y
    }
}

/// Largest magnitude of a cached Gaussian ([`NumpyRandomState`]'s `gauss_bits`) that
/// deserialisation accepts.
///
/// The polar method cannot produce more: `x1`, `x2` are `2·d − 1` with `d` a multiple of
/// 2⁻⁵³, so they are multiples of 2⁻⁵² and a non-zero `r2 = x1² + x2²` is at least 2⁻¹⁰⁴;
/// the cached value `f·x1 = √(−2·ln r2 / r2)·x1` has `|f·x1| ≤ √(−2·ln r2) ≤ √(208·ln 2) ≈
/// 12.0081`. The bound leaves room for rounding; a non-finite or larger value cannot be a
/// cached standard-normal sample of this generator (it would turn the next unseeded reset's
/// joint noise into NaN or a huge offset).
pub const MAX_CACHED_GAUSS: f64 = 12.01;

/// Serde helper storing an `Option<f64>` as its IEEE-754 bit pattern (`Option<u64>`), so the
/// cached Gaussian survives a JSON round trip bit-exactly regardless of the float parser.
/// Deserialisation rejects a value that is not finite or exceeds ±[`MAX_CACHED_GAUSS`].
mod f64_bits_opt {
    use serde::{de::Error, Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        v.map(f64::to_bits).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        let Some(bits) = Option::<u64>::deserialize(d)? else {
            return Ok(None);
        };
        let g = f64::from_bits(bits);
        if g.is_finite() && g.abs() <= super::MAX_CACHED_GAUSS {
            Ok(Some(g))
        } else {
            Err(D::Error::custom(format!(
                "gauss_bits = {bits:#018x} ({g:e}) is not a cached standard-normal sample: it \
                 must be finite with |value| ≤ {} (the most the polar method yields), or null",
                super::MAX_CACHED_GAUSS
            )))
        }
    }
}

/// numpy's legacy `np.random.RandomState(seed)`, restricted to what ManiSkill uses:
/// `normal(loc, scale, size)`.
///
/// Gaussians come from the legacy polar (Marsaglia) method with a cached second value
/// (`legacy_gauss` in numpy's `distributions/legacy`): the cache is part of the state, so
/// it survives [`Clone`] and serde (stored as raw `f64` bits under `"gauss_bits"`). A
/// seeded reset creates a fresh `RandomState`, which discards the cache.
///
/// numpy itself rejects seeds ≥ 2³²; here the seed is reduced mod 2³² like [`Mt19937::new`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NumpyRandomState {
    /// The underlying MT19937.
    mt: Mt19937,
    /// Cached second Gaussian of the last polar pair (`has_gauss`/`gauss`).
    #[serde(rename = "gauss_bits", with = "f64_bits_opt")]
    gauss: Option<f64>,
}

impl NumpyRandomState {
    /// `np.random.RandomState(seed)`: MT19937 `init_genrand(seed mod 2³²)`, no cached
    /// Gaussian.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        NumpyRandomState {
            mt: Mt19937::new(seed),
            gauss: None,
        }
    }

    /// Legacy 53-bit double in [0, 1) from two words `a, b`:
    /// `((a ≫ 5)·67108864 + (b ≫ 6)) / 2⁵³` (`legacy_double` / `random_sample`).
    fn next_double(&mut self) -> f64 {
        let a = f64::from(self.mt.next_u32() >> 5);
        let b = f64::from(self.mt.next_u32() >> 6);
        (a * 67_108_864.0 + b) / 9_007_199_254_740_992.0
    }

    /// Standard normal via the legacy polar method: returns (and clears) the cached value if
    /// present; otherwise draws `x1 = 2·d1 − 1`, `x2 = 2·d2 − 1` until `0 < r2 = x1² + x2² < 1`,
    /// sets `f = √(−2·ln r2 / r2)`, caches `f·x1` and returns `f·x2`.
    fn gauss(&mut self) -> f64 {
        if let Some(g) = self.gauss.take() {
            return g;
        }
        loop {
            let x1 = 2.0 * self.next_double() - 1.0;
            let x2 = 2.0 * self.next_double() - 1.0;
            let r2 = x1 * x1 + x2 * x2;
            if r2 < 1.0 && r2 != 0.0 {
                let f = (-2.0 * r2.ln() / r2).sqrt();
                self.gauss = Some(f * x1);
                return f * x2;
            }
        }
    }

    /// One value of `RandomState.normal(loc, scale)`: `loc + scale·g` in float64. A draw is
    /// made even when `scale == 0` (numpy does the same, so the stream advances identically).
    pub fn normal(&mut self, loc: f64, scale: f64) -> f64 {
        loc + scale * self.gauss()
    }

    /// `RandomState.normal(loc, scale, size=out.len())`, filling `out` in order (row-major for
    /// a `(1, n)` shape).
    pub fn fill_normal(&mut self, loc: f64, scale: f64, out: &mut [f64]) {
        for v in out.iter_mut() {
            *v = self.normal(loc, scale);
        }
    }

    /// One value of `RandomState.uniform(low, high)`: `low + (high − low)·d` for a 53-bit
    /// double `d` in [0, 1).
    pub fn uniform(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.next_double()
    }

    /// One value of `RandomState.randint(2**31)`: numpy's masked rejection sampling, which
    /// for this range keeps the low 31 bits of one MT19937 word.
    pub fn randint_2_31(&mut self) -> u64 {
        u64::from(self.mt.next_u32() & 0x7fff_ffff)
    }

    /// Whether the underlying MT19937 is in its all-zero state ([`Mt19937::is_degenerate`]).
    #[must_use]
    pub fn is_degenerate(&self) -> bool {
        self.mt.is_degenerate()
    }

    /// Whether a cached second Gaussian is pending (numpy's `has_gauss`); the next
    /// [`normal`](Self::normal) then consumes no MT19937 output.
    #[must_use]
    pub fn has_cached_gauss(&self) -> bool {
        self.gauss.is_some()
    }
}

/// Seed of an unseeded torch CPU generator: `c10::default_rng_seed_val = 67280421310721`
/// (`0x3D30_F19C_D101`), the default argument of `at::CPUGeneratorImpl(uint64_t seed_in)`,
/// i.e. what `torch.Generator()` starts from. MT19937 keeps only the low 32 bits
/// (`init_with_uint32`: `state[0] = seed & 0xffffffff` = 4053586177), while
/// `initial_seed()` still reports the full 64-bit value.
///
/// Note: torch's *process-global* default CPU generator is **not** seeded with this value in
/// current PyTorch — `getDefaultCPUGenerator()` uses `getNonDeterministicRandom()`
/// (`/dev/urandom`), so `torch.initial_seed()` differs per process and unseeded upstream
/// resets are not reproducible. This constant is the deterministic stand-in used by
/// [`TorchGenerator::default`].
pub const TORCH_DEFAULT_SEED: u64 = 67_280_421_310_721;

/// torch's CPU generator (`at::CPUGeneratorImpl` over `at::mt19937`) as used by
/// `torch.rand(..., dtype=float32)`.
///
/// `torch.rand` on CPU fills the tensor serially, one `u32` per element in row-major order,
/// each mapped to `(u32 & 0xFFFFFF)·2⁻²⁴` (the **low** 24 bits; `uniform_real_distribution`
/// for float). `rand((b, 3))` therefore consumes 3 words even if only one is used.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TorchGenerator {
    /// Seed as given to `manual_seed` (reported by `initial_seed()`).
    seed: u64,
    /// The underlying MT19937 (seeded with the low 32 bits of `seed`).
    mt: Mt19937,
}

impl TorchGenerator {
    /// `torch.manual_seed(seed)`: a fresh MT19937 with `init_genrand(seed mod 2³²)`.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        TorchGenerator {
            seed,
            mt: Mt19937::new(seed),
        }
    }

    /// The seed this generator was created with (`torch.initial_seed()`).
    #[must_use]
    pub fn initial_seed(&self) -> u64 {
        self.seed
    }

    /// Whether the underlying MT19937 is in its all-zero state ([`Mt19937::is_degenerate`]).
    #[must_use]
    pub fn is_degenerate(&self) -> bool {
        self.mt.is_degenerate()
    }

    /// Next raw 32-bit word (`CPUGeneratorImpl::random()`).
    pub fn next_u32(&mut self) -> u32 {
        self.mt.next_u32()
    }

    /// One float32 of `torch.rand`: `(u32 & 0xFFFFFF) as f32 · 2⁻²⁴` ∈ [0, 1) (exact).
    pub fn rand_f32(&mut self) -> f32 {
        (self.mt.next_u32() & 0x00ff_ffff) as f32 * (1.0 / 16_777_216.0)
    }

    /// `torch.rand(shape)` with `out.len()` elements, row-major (one word per element).
    pub fn fill_rand(&mut self, out: &mut [f32]) {
        for v in out.iter_mut() {
            *v = self.rand_f32();
        }
    }
}

impl Default for TorchGenerator {
    /// A generator seeded with [`TORCH_DEFAULT_SEED`] (67280421310721, i.e. MT19937 seed
    /// 4053586177 after truncation) — torch's `default_rng_seed_val`, the seed of a fresh
    /// `torch.Generator()`. Upstream's process-global generator is seeded from
    /// `/dev/urandom` instead (see [`TORCH_DEFAULT_SEED`]), so this is a reproducible
    /// stand-in, not a bit-exact copy.
    fn default() -> Self {
        TorchGenerator::new(TORCH_DEFAULT_SEED)
    }
}

/// Upstream's `torch.rand(..) * s * 2 - s + c` (docs/tasks.md §1.4, docs/env.md §9) in float32, in that
/// exact order: `((u·s)·2 − s) + c`, each operation rounded to f32 (no fused multiply-add).
/// Maps `u ∈ [0, 1)` to `U(c − s, c + s)`. Because ×2 is exact, `u·s·2 == u·(2s)`, so this
/// also equals the `u·2s − s + c` spelling (and `u·0.2 − 0.1` for `s = 0.1`, `c = 0`, since
/// `0.2f32 == 2·0.1f32`).
#[must_use]
pub fn uniform_scaled(u: f32, s: f32, c: f32) -> f32 {
    u * s * 2.0 - s + c
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOL: f64 = 1e-6;

    fn assert_close(got: &[f64], want: &[f64], tol: f64, what: &str) {
        assert_eq!(got.len(), want.len(), "{what}: length");
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            assert!(
                (g - w).abs() <= tol,
                "{what}[{i}]: got {g}, want {w} (|Δ| = {})",
                (g - w).abs()
            );
        }
    }

    fn rand_vec(g: &mut TorchGenerator, n: usize) -> Vec<f32> {
        let mut v = vec![0f32; n];
        g.fill_rand(&mut v);
        v
    }

    fn to_f64(v: &[f32]) -> Vec<f64> {
        v.iter().map(|&x| x as f64).collect()
    }

    #[test]
    fn mt19937_seed0_first_output() {
        assert_eq!(Mt19937::new(0).next_u32(), 2_357_136_044);
    }

    #[test]
    fn mt19937_seed5489_reference_outputs() {
        let mut mt = Mt19937::new(5489);
        assert_eq!(mt.next_u32(), 3_499_211_612);
        // C++ std::mt19937 conformance value: the 10000th output of the default engine.
        for _ in 1..9999 {
            mt.next_u32();
        }
        assert_eq!(mt.next_u32(), 4_123_659_995);
    }

    #[test]
    fn mt19937_seed_reduced_mod_2_32() {
        let mut a = Mt19937::new(1 << 32);
        let mut b = Mt19937::new(0);
        assert_eq!(a, b);
        for _ in 0..1000 {
            assert_eq!(a.next_u32(), b.next_u32());
        }
    }

    #[test]
    fn mt19937_serde_round_trip_and_validation() {
        let mut mt = Mt19937::new(42);
        for _ in 0..700 {
            mt.next_u32();
        }
        let json = serde_json::to_string(&mt).unwrap();
        let mut back: Mt19937 = serde_json::from_str(&json).unwrap();
        assert_eq!(back, mt);
        for _ in 0..1000 {
            assert_eq!(back.next_u32(), mt.next_u32());
        }
        assert!(serde_json::from_str::<Mt19937>(r#"{"state":[1,2,3],"index":0}"#).is_err());
        let bad_index = format!(r#"{{"state":{:?},"index":625}}"#, vec![0u32; N]);
        assert!(serde_json::from_str::<Mt19937>(&bad_index).is_err());
    }

    #[test]
    fn numpy_and_torch_share_the_u32_stream() {
        let mut t = TorchGenerator::new(7);
        let mut m = Mt19937::new(7);
        for _ in 0..100 {
            assert_eq!(t.next_u32(), m.next_u32());
        }
    }

    #[test]
    fn torch_seed0_rand_vectors() {
        let mut g = TorchGenerator::new(0);
        let r1 = rand_vec(&mut g, 2);
        let r2 = rand_vec(&mut g, 3);
        let r3 = rand_vec(&mut g, 2);
        let r4 = rand_vec(&mut g, 1);
        assert_close(&to_f64(&r1), &[0.496257, 0.768222], TOL, "rand(2)");
        assert_close(
            &to_f64(&r2),
            &[0.088477, 0.132030, 0.307423],
            TOL,
            "rand(3)",
        );
        assert_close(&to_f64(&r3), &[0.634079, 0.490093], TOL, "rand(2)#2");
        assert_close(&to_f64(&r4), &[0.896445], TOL, "rand(1)");
        // Low-24-bit rule, checked on the raw word: first output for seed 0.
        let u = (2_357_136_044u32 & 0x00ff_ffff) as f32 / 16_777_216.0;
        assert_eq!(r1[0].to_bits(), u.to_bits());
    }

    #[test]
    fn torch_default_seed() {
        let d = TorchGenerator::default();
        assert_eq!(d.initial_seed(), 67_280_421_310_721);
        assert_eq!(TORCH_DEFAULT_SEED as u32, 4_053_586_177);
        // Only the low 32 bits reach MT19937.
        let mut a = d.clone();
        let mut b = TorchGenerator::new(4_053_586_177);
        for _ in 0..1000 {
            assert_eq!(a.next_u32(), b.next_u32());
        }
    }

    #[test]
    fn numpy_seed0_normal_vector() {
        let mut rs = NumpyRandomState::new(0);
        let got: Vec<f64> = (0..9).map(|_| rs.normal(0.0, 0.02)).collect();
        let want = [
            0.035281, 0.008003, 0.019575, 0.044818, 0.037351, -0.019546, 0.019002, -0.003027,
            -0.002064,
        ];
        assert_close(&got, &want, TOL, "normal(0, 0.02, 9)");
        // fill_normal is the same stream.
        let mut rs2 = NumpyRandomState::new(0);
        let mut out = [0.0; 9];
        rs2.fill_normal(0.0, 0.02, &mut out);
        for (a, b) in out.iter().zip(&got) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        assert_eq!(rs, rs2);
    }

    #[test]
    fn numpy_loc_scale_and_zero_scale_advance() {
        let mut a = NumpyRandomState::new(3);
        let mut b = NumpyRandomState::new(3);
        let g = a.normal(0.0, 1.0);
        assert_eq!(b.normal(1.5, 2.0).to_bits(), (1.5 + 2.0 * g).to_bits());
        // scale 0 still draws.
        let mut c = NumpyRandomState::new(3);
        assert_eq!(c.normal(0.0, 0.0), 0.0);
        assert_eq!(c, b);
    }

    #[test]
    fn numpy_cached_gauss_survives_clone_and_serde() {
        let mut rs = NumpyRandomState::new(0);
        let mut noise = [0.0; 9];
        rs.fill_normal(0.0, 0.02, &mut noise);
        assert!(rs.has_cached_gauss(), "9 draws (odd) leave a cached value");
        let json = serde_json::to_string(&rs).unwrap();
        let mut from_json: NumpyRandomState = serde_json::from_str(&json).unwrap();
        assert_eq!(from_json, rs);
        let mut cloned = rs.clone();
        // The 10th value of the original stream is the cached one (no MT output consumed).
        let mut full = NumpyRandomState::new(0);
        let mut ten = [0.0; 10];
        full.fill_normal(0.0, 0.02, &mut ten);
        let mt_before = rs.mt.clone();
        let next = rs.normal(0.0, 0.02);
        assert_eq!(rs.mt, mt_before, "cached value consumes no MT output");
        assert!(!rs.has_cached_gauss());
        assert_eq!(next.to_bits(), ten[9].to_bits());
        assert_eq!(cloned.normal(0.0, 0.02).to_bits(), next.to_bits());
        assert_eq!(from_json.normal(0.0, 0.02).to_bits(), next.to_bits());
        // And the streams stay in lock-step afterwards.
        for _ in 0..50 {
            let x = rs.normal(0.0, 1.0).to_bits();
            assert_eq!(cloned.normal(0.0, 1.0).to_bits(), x);
            assert_eq!(from_json.normal(0.0, 1.0).to_bits(), x);
        }
        // A fresh RandomState (seeded reset) discards the cache.
        assert!(!NumpyRandomState::new(0).has_cached_gauss());
    }

    #[test]
    fn cached_gauss_bound_covers_the_polar_method_and_rejects_the_rest() {
        // The largest cached value the polar method can yield: x1 = 2⁻⁵², x2 = 0.
        let x1 = 2f64.powi(-52);
        let r2 = x1 * x1;
        let max = (-2.0 * r2.ln() / r2).sqrt() * x1;
        assert!(max > 12.0 && max <= MAX_CACHED_GAUSS, "{max}");
        let mut rs = NumpyRandomState::new(0);
        rs.fill_normal(0.0, 1.0, &mut [0.0; 3]);
        let json = serde_json::to_string(&rs).unwrap();
        let cached = rs.gauss.unwrap().to_bits();
        assert!(json.contains(&format!("\"gauss_bits\":{cached}")), "{json}");
        let with = |bits: u64| json.replace(&cached.to_string(), &bits.to_string());
        for ok in [max, -max, 0.0, -1.5] {
            let back: NumpyRandomState = serde_json::from_str(&with(ok.to_bits())).unwrap();
            assert_eq!(back.gauss, Some(ok));
        }
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -12.02] {
            let e = serde_json::from_str::<NumpyRandomState>(&with(bad.to_bits()))
                .unwrap_err()
                .to_string();
            assert!(e.contains("gauss_bits = 0x") && e.contains("12.01"), "{e}");
        }
    }

    /// Panda rest qpos + N(0, 0.02) noise on all 9 entries (fingers then reset to 0.04),
    /// float64 sum then the float32 round trip of PhysX.
    fn panda_qpos(seed: u64) -> Vec<f64> {
        // The Panda's table-scene rest pose (docs/tasks.md §0.2).
        use std::f64::consts::PI;
        let rest = [
            0.0,
            PI / 8.0,
            0.0,
            -5.0 * PI / 8.0,
            0.0,
            3.0 * PI / 4.0,
            PI / 4.0,
            0.04,
            0.04,
        ];
        let mut noise = [0.0; 9];
        NumpyRandomState::new(seed).fill_normal(0.0, 0.02, &mut noise);
        let mut q: Vec<f64> = rest.iter().zip(&noise).map(|(r, n)| r + n).collect();
        q[7] = 0.04;
        q[8] = 0.04;
        q.iter().map(|&x| x as f32 as f64).collect()
    }

    /// docs/tasks.md §1.4 for panda: s = 0.1, c = (0, 0), h = 0.02, max_goal_height = 0.3.
    /// Returns (cube xyz, cube yaw quaternion wxyz, goal xyz).
    fn pick_cube(seed: u64) -> ([f64; 3], [f64; 4], [f64; 3]) {
        let (s, c, h, max_h) = (0.1f32, [0.0f32, 0.0], 0.02f32, 0.3f32);
        let mut g = TorchGenerator::new(seed);
        let u1 = rand_vec(&mut g, 2);
        let u2 = rand_vec(&mut g, 3);
        let u3 = rand_vec(&mut g, 2);
        let u4 = rand_vec(&mut g, 1);
        let cube = [
            uniform_scaled(u1[0], s, c[0]) as f64,
            uniform_scaled(u1[1], s, c[1]) as f64,
            h as f64,
        ];
        let yaw = (u2[2] * (2.0 * std::f32::consts::PI)) as f64;
        let (mut w, mut z) = ((yaw / 2.0).cos(), (yaw / 2.0).sin());
        if w < 0.0 {
            (w, z) = (-w, -z);
        }
        let goal = [
            uniform_scaled(u3[0], s, c[0]) as f64,
            uniform_scaled(u3[1], s, c[1]) as f64,
            (u4[0] * max_h + h) as f64,
        ];
        (cube, [w, 0.0, 0.0, z], goal)
    }

    #[test]
    fn pick_cube_seed0_end_to_end() {
        let (cube, q, goal) = pick_cube(0);
        assert_close(&cube, &[-0.000749, 0.053644, 0.02], TOL, "cube");
        assert_close(&q, &[0.568761, 0.0, 0.0, 0.822503], TOL, "cube.q");
        assert_close(&goal, &[0.026816, -0.001981, 0.288933], TOL, "goal");
        let want = [
            0.035281, 0.400702, 0.019575, -1.918678, 0.037351, 2.336649, 0.8044, 0.04, 0.04,
        ];
        assert_close(&panda_qpos(0), &want, TOL, "qpos");
    }

    #[test]
    fn pick_cube_seed1_end_to_end() {
        let (cube, q, goal) = pick_cube(1);
        assert_close(&cube, &[0.051526, -0.044138, 0.02], TOL, "cube");
        assert_close(&q, &[0.995772, 0.0, 0.0, 0.091861], TOL, "cube.q");
        assert_close(&goal, &[0.059972, -0.020573, 0.246312], TOL, "goal");
        let want = [
            0.032487, 0.380464, -0.010563, -1.984955, 0.017308, 2.310164, 0.820294, 0.04, 0.04,
        ];
        assert_close(&panda_qpos(1), &want, TOL, "qpos");
    }

    #[test]
    fn uniform_scaled_float32_order() {
        // Bit-identical to the spelled-out f32 expression and to u·(2s) − s + c.
        let mut g = TorchGenerator::new(123);
        for _ in 0..1000 {
            let u = g.rand_f32();
            for (s, c) in [(0.1f32, 0.0f32), (0.05, -0.46), (0.05, -0.25)] {
                let want = ((u * s) * 2.0 - s) + c;
                assert_eq!(uniform_scaled(u, s, c).to_bits(), want.to_bits());
                assert_eq!(
                    uniform_scaled(u, s, c).to_bits(),
                    (u * (2.0 * s) - s + c).to_bits()
                );
            }
            assert_eq!(
                uniform_scaled(u, 0.1, 0.0).to_bits(),
                (u * 0.2f32 - 0.1f32).to_bits()
            );
        }
    }

    /// docs/tasks.md §2.2 (PokeCube) — extra cross-check of the torch stream and f32 order.
    #[test]
    fn poke_cube_seeds_0_1() {
        let cases = [
            (0u64, [-0.000749, 0.053644], [0.219251, -0.038515], 0.319251),
            (1, [0.051526, -0.044138], [0.271526, -0.094144], 0.371526),
        ];
        for (seed, peg_xy, cube_xy, goal_x) in cases {
            let mut g = TorchGenerator::new(seed);
            let u1 = rand_vec(&mut g, 3);
            let u2 = rand_vec(&mut g, 3);
            let _u3 = rand_vec(&mut g, 3);
            let peg = [u1[0] * 0.2 - 0.1, u1[1] * 0.2 - 0.1];
            let cube = [peg[0] + 0.12 + 0.1, u2[1] * 0.2 - 0.1];
            assert_close(&to_f64(&peg), &peg_xy, TOL, "peg");
            assert_close(&to_f64(&cube), &cube_xy, TOL, "cube");
            assert_close(&[(cube[0] + 0.1) as f64], &[goal_x], TOL, "goal.x");
        }
    }

    /// docs/tasks.md §3.2 (PlaceSphere) — extra cross-check of the torch stream.
    #[test]
    fn place_sphere_seeds_0_1() {
        let cases = [
            (0u64, [-0.075187, 0.053644], [0.008848, -0.073594]),
            (1, [-0.062118, -0.044138], [0.040307, 0.046937]),
        ];
        for (seed, sphere_xy, bin_xy) in cases {
            let mut g = TorchGenerator::new(seed);
            let u = rand_vec(&mut g, 4);
            let sphere = [u[0] * 0.05 - 0.1, u[1] * 0.2 - 0.1];
            let bin = [u[2] * 0.1, u[3] * 0.2 - 0.1];
            assert_close(&to_f64(&sphere), &sphere_xy, TOL, "sphere");
            assert_close(&to_f64(&bin), &bin_xy, TOL, "bin");
        }
    }
}
