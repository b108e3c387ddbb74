//! Random physics buffers near a reference state: what `reward_termination` and `observe` read
//! (`d.qpos`, `d.qvel`, `d.xpos`, `d.xquat`, `d.subtree_com`, `d.cvel`, docs/env.md). The
//! kernels only do arithmetic on these buffers, so they need not be a consistent MuJoCo state;
//! they are the reference perturbed by a per-env scale, so that the tracking errors, rewards and
//! observations take realistic values. Their sizes are the character's ([`Shape`]).

use instantmimic::env::PhysicsSizes;
use instantmimic::env::layout::reference_layout;
use instantmimic::kernels::ReferenceLayout;
use instantmimic::motion::Character;
use instantmimic::motion::table::TableLayout;

use super::Clip;
use super::quat::{qexp, quat_at64, wxyz};
use super::rng::Sampler;

/// A character's shape as the kernels see it: the physics buffers' sizes and the reference
/// table's row.
#[derive(Clone, Debug)]
pub struct Shape {
    pub sizes: PhysicsSizes,
    pub table: TableLayout,
    /// qpos addresses where a quaternion starts (the root's rotation, then the ball joints).
    pub quaternions: Vec<usize>,
}

impl Shape {
    pub fn of(character: &Character) -> Shape {
        Shape {
            sizes: PhysicsSizes::of(character),
            table: TableLayout::for_character(character),
            quaternions: character.quaternion_qpos_addresses(),
        }
    }

    pub fn nq(&self) -> usize {
        self.sizes.nq
    }

    pub fn nv(&self) -> usize {
        self.sizes.nv
    }

    pub fn nu(&self) -> usize {
        self.sizes.nu
    }

    /// MuJoCo bodies, the world (id 0) included.
    pub fn nbody(&self) -> usize {
        self.sizes.nbody
    }

    /// Real bodies (body index b = MuJoCo id - 1).
    pub fn bodies(&self) -> usize {
        self.sizes.nbody - 1
    }

    /// The row layout as the kernels take it.
    pub fn reference_layout(&self) -> ReferenceLayout {
        reference_layout(&self.table).expect("the row fits the kernels")
    }
}

/// The physics buffers of `n` envs, f32, env first.
#[derive(Clone, Debug)]
pub struct PhysicsBatch {
    pub shape: Shape,
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
    pub fn new(shape: &Shape, n: usize) -> PhysicsBatch {
        let (nq, nv, nbody) = (shape.nq(), shape.nv(), shape.nbody());
        PhysicsBatch {
            shape: shape.clone(),
            n,
            qpos: vec![0.0; n * nq],
            qvel: vec![0.0; n * nv],
            xpos: vec![0.0; n * nbody * 3],
            xquat: vec![0.0; n * nbody * 4],
            subtree_com: vec![0.0; n * nbody * 3],
            cvel: vec![0.0; n * nbody * 6],
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
        let l = self.shape.table;
        let (nq, nv, nbody) = (self.shape.nq(), self.shape.nv(), self.shape.nbody());
        let row = clip.0.lookup(clip.1, t);
        let angle = 0.05 * scale;
        let position = 0.03 * scale;
        let velocity = 0.5 * scale;

        let mut qpos: Vec<f64> = row[l.qpos..l.qpos + nq].to_vec();
        for (i, v) in qpos.iter_mut().enumerate() {
            // Hinges (and the root position) get additive noise; quaternions are rotated below.
            *v += if i < 3 { position } else { angle } * rng.normal();
        }
        for &a in &self.shape.quaternions {
            let q = quat_at64(&row, l.qpos + a) * qexp(rng.normal3(angle));
            qpos[a..a + 4].copy_from_slice(&wxyz(&q));
        }
        put(&mut self.qpos, e * nq, &qpos);
        let qvel: Vec<f64> = (0..nv)
            .map(|k| row[l.qvel + k] + velocity * rng.normal())
            .collect();
        put(&mut self.qvel, e * nv, &qvel);

        // The world body: at the origin, unrotated, at rest.
        put(&mut self.xquat, e * nbody * 4, &[1.0, 0.0, 0.0, 0.0]);
        for b in 0..self.shape.bodies() {
            let id = b + 1;
            let p = add3(&row, l.body_pos + 3 * b, rng.normal3(position));
            put(&mut self.xpos, (e * nbody + id) * 3, &p);
            let q = quat_at64(&row, l.body_quat + 4 * b) * qexp(rng.normal3(angle));
            put(&mut self.xquat, (e * nbody + id) * 4, &wxyz(&q));
            let w = add3(&row, l.body_angvel + 3 * b, rng.normal3(velocity));
            let v = add3(&row, l.body_linvel + 3 * b, rng.normal3(velocity));
            put(&mut self.cvel, (e * nbody + id) * 6, &w);
            put(&mut self.cvel, (e * nbody + id) * 6 + 3, &v);
            // Subtree COMs of the other bodies are not read; the root's is the whole body's.
            let c = if b == 0 {
                add3(&row, l.com_pos, rng.normal3(position))
            } else {
                add3(&row, l.body_pos + 3 * b, rng.normal3(position))
            };
            put(&mut self.subtree_com, (e * nbody + id) * 3, &c);
        }
        put(
            &mut self.subtree_com,
            e * nbody * 3,
            &add3(&row, l.com_pos, [0.0; 3]),
        );
    }
}
