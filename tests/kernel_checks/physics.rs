//! Random physics buffers near a reference state: what `reward_termination` and `observe` read
//! (`d.qpos`, `d.qvel`, `d.xpos`, `d.xquat`, `d.subtree_com`, `d.cvel`, docs/env.md). The
//! kernels only do arithmetic on these buffers, so they need not be a consistent MuJoCo state;
//! they are the reference perturbed by a per-env scale, so that the tracking errors, rewards and
//! observations take realistic values.

use instantmimic::motion::table::{HUMANOID_LAYOUT, HUMANOID_QPOS_QUATERNIONS};

use super::Clip;
use super::quat::{qexp, quat_at64, wxyz};
use super::rng::Sampler;

pub const NQ: usize = 43;
pub const NV: usize = 34;
pub const NU: usize = 28;
/// MuJoCo bodies, the world (id 0) included.
pub const NBODY: usize = 16;
/// Real bodies (body index b = MuJoCo id - 1).
pub const BODIES: usize = 15;

/// The physics buffers of `n` envs, f32, env first.
#[derive(Clone, Debug)]
pub struct PhysicsBatch {
    pub n: usize,
    pub qpos: Vec<f32>,
    pub qvel: Vec<f32>,
    pub xpos: Vec<f32>,
    pub xquat: Vec<f32>,
    pub subtree_com: Vec<f32>,
    pub cvel: Vec<f32>,
}

fn put(dst: &mut [f32], at: usize, values: &[f64]) {
    for (d, v) in dst[at..at + values.len()].iter_mut().zip(values) {
        *d = *v as f32;
    }
}

fn add3(a: &[f64], at: usize, b: [f64; 3]) -> [f64; 3] {
    [a[at] + b[0], a[at + 1] + b[1], a[at + 2] + b[2]]
}

impl PhysicsBatch {
    pub fn new(n: usize) -> PhysicsBatch {
        PhysicsBatch {
            n,
            qpos: vec![0.0; n * NQ],
            qvel: vec![0.0; n * NV],
            xpos: vec![0.0; n * NBODY * 3],
            xquat: vec![0.0; n * NBODY * 4],
            subtree_com: vec![0.0; n * NBODY * 3],
            cvel: vec![0.0; n * NBODY * 6],
        }
    }

    /// Env `e` at the reference state of clip `c` of `clip` at time `t`, perturbed with noise
    /// of `scale` (1: joint angles off by ~0.05 rad, velocities by ~0.5, positions by ~3 cm).
    pub fn set_near_reference(
        &mut self,
        e: usize,
        clip: (&Clip, usize),
        t: f64,
        scale: f64,
        rng: &mut Sampler,
    ) {
        let l = HUMANOID_LAYOUT;
        let row = clip.0.lookup(clip.1, t);
        let angle = 0.05 * scale;
        let position = 0.03 * scale;
        let velocity = 0.5 * scale;

        let mut qpos: Vec<f64> = row[l.qpos..l.qpos + NQ].to_vec();
        for (i, v) in qpos.iter_mut().enumerate() {
            // Hinges (and the root position) get additive noise; quaternions are rotated below.
            *v += if i < 3 { position } else { angle } * rng.normal();
        }
        for &a in &HUMANOID_QPOS_QUATERNIONS {
            let q = quat_at64(&row, l.qpos + a) * qexp(rng.normal3(angle));
            qpos[a..a + 4].copy_from_slice(&wxyz(&q));
        }
        put(&mut self.qpos, e * NQ, &qpos);
        let qvel: Vec<f64> = (0..NV)
            .map(|k| row[l.qvel + k] + velocity * rng.normal())
            .collect();
        put(&mut self.qvel, e * NV, &qvel);

        // The world body: at the origin, unrotated, at rest.
        put(&mut self.xquat, e * NBODY * 4, &[1.0, 0.0, 0.0, 0.0]);
        for b in 0..BODIES {
            let id = b + 1;
            let p = add3(&row, l.body_pos + 3 * b, rng.normal3(position));
            put(&mut self.xpos, (e * NBODY + id) * 3, &p);
            let q = quat_at64(&row, l.body_quat + 4 * b) * qexp(rng.normal3(angle));
            put(&mut self.xquat, (e * NBODY + id) * 4, &wxyz(&q));
            let w = add3(&row, l.body_angvel + 3 * b, rng.normal3(velocity));
            let v = add3(&row, l.body_linvel + 3 * b, rng.normal3(velocity));
            put(&mut self.cvel, (e * NBODY + id) * 6, &w);
            put(&mut self.cvel, (e * NBODY + id) * 6 + 3, &v);
            // Subtree COMs of the other bodies are not read; the root's is the whole body's.
            let c = if b == 0 {
                add3(&row, l.com_pos, rng.normal3(position))
            } else {
                add3(&row, l.body_pos + 3 * b, rng.normal3(position))
            };
            put(&mut self.subtree_com, (e * NBODY + id) * 3, &c);
        }
        put(
            &mut self.subtree_com,
            e * NBODY * 3,
            &add3(&row, l.com_pos, [0.0; 3]),
        );
    }
}
