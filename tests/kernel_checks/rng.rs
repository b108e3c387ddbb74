//! Random numbers: the test's own inputs ([`Sampler`], seeded), and a twin of Warp's
//! counter-based generator (`warp/native/rand.h`) so that the references of `reset_masked` and
//! `gaussian_sample` know which numbers the kernels drew.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};

/// Seeded inputs for the cases.
pub struct Sampler(StdRng);

impl Sampler {
    pub fn new(seed: u64) -> Sampler {
        Sampler(StdRng::seed_from_u64(seed))
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.0.random::<f64>()
    }

    pub fn normal(&mut self) -> f64 {
        StandardNormal.sample(&mut self.0)
    }

    /// A vector of 3 independent N(0, sigma^2).
    pub fn normal3(&mut self, sigma: f64) -> [f64; 3] {
        [
            sigma * self.normal(),
            sigma * self.normal(),
            sigma * self.normal(),
        ]
    }

    /// An integer in [lo, hi).
    pub fn index(&mut self, lo: usize, hi: usize) -> usize {
        self.0.random_range(lo..hi)
    }

    pub fn chance(&mut self, p: f64) -> bool {
        self.0.random::<f64>() < p
    }
}

/// Warp's `rand_pcg` (Jarzynski and Olano's PCG hash).
pub fn rand_pcg(state: u32) -> u32 {
    let b = state.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let c = ((b >> ((b >> 28) + 4)) ^ b).wrapping_mul(277_803_737);
    (c >> 22) ^ c
}

/// Which of the two uniforms of `randn` goes into the radius. Warp computes
/// `sqrt(-2 log(randf(state) + eps)) * cos(2 pi randf(state))`, and C++ leaves the order in
/// which the two operands (and so the two draws) are evaluated to the compiler: LLVM on the CPU
/// and NVRTC on the GPU need not agree. The references try both and keep the one that fits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RandnOrder {
    RadiusFirst,
    AngleFirst,
}

/// `RANDN_EPSILON` in rand.h.
const RANDN_EPSILON: f32 = 5.96e-8;
/// `M_PI_F`.
const PI_F32: f32 = std::f32::consts::PI;

/// Warp's random state for `wp.rand_init(seed, offset)`.
pub struct WarpRandom {
    state: u32,
    order: RandnOrder,
}

impl WarpRandom {
    pub fn new(seed: i32, offset: i32, order: RandnOrder) -> WarpRandom {
        WarpRandom {
            state: rand_pcg((seed as u32).wrapping_add(rand_pcg(offset as u32))),
            order,
        }
    }

    /// `wp.randf`: exactly the kernel's f32.
    pub fn randf(&mut self) -> f32 {
        self.state = rand_pcg(self.state);
        (self.state >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// `wp.randn` in f64 from the kernel's own f32 uniform inputs (the f32 additions and products
    /// that form the arguments are reproduced exactly; log, sqrt and cos are in f64).
    pub fn randn(&mut self) -> f64 {
        let first = self.randf();
        let second = self.randf();
        let (radius_u, angle_u) = match self.order {
            RandnOrder::RadiusFirst => (first, second),
            RandnOrder::AngleFirst => (second, first),
        };
        let r = f64::from(radius_u + RANDN_EPSILON);
        let a = f64::from(2.0f32 * PI_F32 * angle_u);
        (-2.0 * r.ln()).sqrt() * a.cos()
    }
}

/// The random stream offset of env `n` at step `t` (reset.py and policy.py), with the kernel's
/// 32-bit wrapping arithmetic.
pub fn stream_offset(iteration: i32, horizon: i32, t: i32, num_envs: i32, n: i32) -> i32 {
    iteration
        .wrapping_mul(horizon)
        .wrapping_add(t)
        .wrapping_mul(num_envs)
        .wrapping_add(n)
}
