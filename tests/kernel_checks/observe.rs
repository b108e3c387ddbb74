//! `observe` (kernels_py/env/observe.py; docs/env.md, "Observation"), block by block.
//!
//! Reference: from the same physics buffers, in f64: everything in the heading frame of the
//! simulated root (`H` = minus the yaw of the root's forward axis), positions relative to the root
//! body's origin, rotations as the first two columns of the rotation matrix, body velocities at
//! the body origins (`cvel` is COM-based), future reference end effectors and the root target
//! of the env's clip from `MotionLibrary::lookup` (a single clip: the library of one), over the
//! character's tracked bodies (the first, the root, left out of the positions); with
//! `reference_bodies`, each tracked body's reference at
//! `ref_time + dt` against the simulated body (position difference in the heading frame, the
//! rotation `conj(q) q_ref` in the body's frame, 6D). Each block is compared on its own; the row
//! is as wide as `layout::observation_size` says, and padding columns after it must stay
//! untouched.

use instantmimic::env::layout::{
    JointLayout, observation_params, observation_size, observe_threads_per_env,
};
use instantmimic::kernels::{OBSERVE, ObservationParams};
use instantmimic::train::ObsConfig;
use nalgebra::Vector3;

use super::compare::{Report, wide};
use super::physics::PhysicsBatch;
use super::program::{Arg, Program, StructArg};
use super::quat::{Quat, heading_inverse, qexp, quat_at, quat_at64, tan_norm, vec3, vec3_64, wxyz};
use super::rng::Sampler;
use super::{CONTROL_DT, Check, Clip, Fixture, nan_f32};

/// Columns after the observation that the kernel must not write.
const PADDING: usize = 3;
/// Root forward axes closer to vertical than this (horizontal length) are avoided: the heading
/// is undefined there, and f32 and f64 may pick different ones.
const MIN_FORWARD_XY: f64 = 0.05;

/// One block of the observation: name and values.
pub struct Block {
    pub name: String,
    pub values: Vec<f64>,
    /// Parts compared on their own too: name and columns within the block.
    pub parts: Vec<(String, Vec<usize>)>,
}

fn add(blocks: &mut Vec<Block>, name: String, values: Vec<f64>) {
    blocks.push(Block {
        name,
        values,
        parts: Vec::new(),
    });
}

fn rotated(h: &Quat, v: Vector3<f64>) -> Vec<f64> {
    let r = h * v;
    vec![r.x, r.y, r.z]
}

/// The f64 observation of env `e`, which tracks clip `clip.1` of `clip.0`, as blocks in the
/// kernel's order.
pub fn reference_blocks(
    clip: (&Clip, usize),
    layout: &JointLayout,
    params: &ObservationParams,
    physics: &PhysicsBatch,
    actions: &[f32],
    ref_time: f32,
    e: usize,
) -> Vec<Block> {
    let shape = &physics.shape;
    let l = shape.table;
    let (nq, nv, nu, nbody) = (shape.nq(), shape.nv(), shape.nu(), shape.nbody());
    let qpos = &physics.qpos[e * nq..(e + 1) * nq];
    let qvel = &physics.qvel[e * nv..(e + 1) * nv];
    let body = |b: usize| e * nbody + b + 1;
    let tracked: Vec<usize> = layout.tracked_bodies.iter().map(|&b| b as usize).collect();
    let root_q = quat_at(qpos, 3);
    let root_p = vec3(&physics.xpos, body(0) * 3);
    let h = heading_inverse(&root_q);
    let com = vec3(&physics.subtree_com, body(0) * 3);
    let mut blocks = Vec::new();

    add(&mut blocks, "root height".into(), vec![f64::from(qpos[2])]);
    add(
        &mut blocks,
        "root rotation 6D".into(),
        tan_norm(&(h * root_q)).to_vec(),
    );
    add(
        &mut blocks,
        "root linear velocity".into(),
        rotated(&h, vec3(qvel, 0)),
    );
    add(
        &mut blocks,
        "root angular velocity".into(),
        rotated(&h, root_q * vec3(qvel, 3)),
    );
    add(
        &mut blocks,
        "body positions".into(),
        tracked[1..]
            .iter()
            .flat_map(|&b| rotated(&h, vec3(&physics.xpos, body(b) * 3) - root_p))
            .collect(),
    );
    add(
        &mut blocks,
        "body rotations 6D".into(),
        tracked
            .iter()
            .flat_map(|&b| tan_norm(&(h * quat_at(&physics.xquat, body(b) * 4))))
            .collect(),
    );
    add(
        &mut blocks,
        "body linear velocities".into(),
        tracked
            .iter()
            .flat_map(|&b| {
                let w = vec3(&physics.cvel, body(b) * 6);
                let v = vec3(&physics.cvel, body(b) * 6 + 3)
                    + w.cross(&(vec3(&physics.xpos, body(b) * 3) - com));
                rotated(&h, v)
            })
            .collect(),
    );
    add(
        &mut blocks,
        "body angular velocities".into(),
        tracked
            .iter()
            .flat_map(|&b| rotated(&h, vec3(&physics.cvel, body(b) * 6)))
            .collect(),
    );
    for f in 1..=params.future_frames {
        // The kernel's f32 time (ref_time is an f32 quantity).
        let t = ref_time + (f * params.future_spacing) as f32 * params.dt;
        let row = clip.0.lookup(clip.1, f64::from(t));
        let mut positions = Vec::new();
        let mut rotations = Vec::new();
        for &b in &layout.end_effectors {
            let b = b as usize;
            positions.push(rotated(&h, vec3_64(&row, l.body_pos + 3 * b) - root_p));
            rotations.push(tan_norm(&(h * quat_at64(&row, l.body_quat + 4 * b))).to_vec());
        }
        // The kernel interleaves them: per end effector, position then rotation.
        let interleaved: Vec<f64> = positions
            .iter()
            .zip(&rotations)
            .flat_map(|(p, r)| p.iter().chain(r).copied())
            .collect();
        let columns = |offset: usize, count: usize| -> Vec<usize> {
            (0..layout.end_effectors.len())
                .flat_map(|k| (0..count).map(move |c| 9 * k + offset + c))
                .collect()
        };
        blocks.push(Block {
            name: format!("future frame {f} end effectors"),
            values: interleaved,
            parts: vec![
                (
                    format!("future frame {f} end effector positions"),
                    columns(0, 3),
                ),
                (
                    format!("future frame {f} end effector rotations 6D"),
                    columns(3, 6),
                ),
            ],
        });
    }
    if params.prev_action != 0 {
        add(
            &mut blocks,
            "previous action".into(),
            wide(&actions[e * nu..(e + 1) * nu]),
        );
    }
    if params.root_target != 0 {
        let row = clip.0.lookup(clip.1, f64::from(ref_time + params.dt));
        add(
            &mut blocks,
            "root target position".into(),
            rotated(&h, vec3_64(&row, l.qpos) - root_p),
        );
        add(
            &mut blocks,
            "root target rotation 6D".into(),
            tan_norm(&(h * quat_at64(&row, l.qpos + 3))).to_vec(),
        );
    }
    if params.reference_bodies != 0 {
        let row = clip.0.lookup(clip.1, f64::from(ref_time + params.dt));
        let values: Vec<f64> = tracked
            .iter()
            .flat_map(|&b| {
                let p = vec3(&physics.xpos, body(b) * 3);
                let q = quat_at(&physics.xquat, body(b) * 4);
                let position = rotated(&h, vec3_64(&row, l.body_pos + 3 * b) - p);
                let rotation = tan_norm(&(q.inverse() * quat_at64(&row, l.body_quat + 4 * b)));
                position.into_iter().chain(rotation)
            })
            .collect();
        let columns = |offset: usize, count: usize| -> Vec<usize> {
            (0..tracked.len())
                .flat_map(|i| (0..count).map(move |c| 9 * i + offset + c))
                .collect()
        };
        blocks.push(Block {
            name: "reference bodies".into(),
            values,
            parts: vec![
                ("reference body positions".into(), columns(0, 3)),
                ("reference body rotations 6D".into(), columns(3, 6)),
            ],
        });
    }
    blocks
}

fn case(fx: &Fixture, clip_index: usize, n: usize, obs: ObsConfig, seed: u64) -> Check {
    let clip = fx.clips()[clip_index].clone();
    let clip_name = clip.name.clone();
    let layout = fx.layout.clone();
    let params = observation_params(&obs, CONTROL_DT);
    let width = observation_size(&obs, layout.observation_counts());
    let stride = width + PADDING;
    let shape = fx.shape.clone();
    let (nq, nv, nu, nbody) = (shape.nq(), shape.nv(), shape.nu(), shape.nbody());
    let mut rng = Sampler::new(seed);
    let clip_id = clip.clip_ids(n, &mut rng);
    let mut physics = PhysicsBatch::new(&shape, n);
    let mut ref_time = vec![0.0f32; n];
    for (e, time) in ref_time.iter_mut().enumerate() {
        let c = clip_id[e] as usize;
        let d = clip.duration(c);
        loop {
            let t = if clip.wraps(c) {
                rng.uniform(0.0, 5.0 * d)
            } else {
                // Future frames reach past the end of a clamped clip for some envs.
                rng.uniform(0.0, d)
            };
            *time = t as f32;
            physics.set_near_reference(
                e,
                (&clip, c),
                f64::from(*time),
                rng.uniform(0.3, 2.0),
                &mut rng,
            );
            // Half the envs turned about +z: other headings than the clip's.
            if e % 2 == 1 {
                let at = e * nq + 3;
                let q = qexp([0.0, 0.0, rng.uniform(-3.1, 3.1)]) * quat_at(&physics.qpos, at);
                for (c, v) in wxyz(&q).iter().enumerate() {
                    physics.qpos[at + c] = *v as f32;
                }
            }
            let forward = quat_at(&physics.qpos, e * nq + 3) * Vector3::x();
            if forward.xy().norm() > MIN_FORWARD_XY {
                break;
            }
        }
    }
    let actions: Vec<f32> = (0..n * nu).map(|_| rng.uniform(-1.5, 1.5) as f32).collect();

    let tracked = layout.tracked_bodies.clone();
    let mut p = Program::new(format!(
        "observe: {clip_name}, {n} envs, {} tracked bodies, {} future frames every {} steps, prev action {}, root target {}, reference bodies {} ({width} values)",
        tracked.len(),
        obs.future_frames,
        obs.future_spacing,
        obs.prev_action,
        obs.root_target,
        obs.reference_bodies
    ));
    let ee = layout.end_effectors.clone();
    let threads = n * observe_threads_per_env(tracked.len());
    let args = vec![
        p.f32("qpos", &[n, nq], physics.qpos.clone()),
        p.f32("qvel", &[n, nv], physics.qvel.clone()),
        p.f32("xpos", &[n, nbody, 3], physics.xpos.clone()),
        p.f32("xquat", &[n, nbody, 4], physics.xquat.clone()),
        p.f32("cvel", &[n, nbody, 6], physics.cvel.clone()),
        p.f32("subtree_com", &[n, nbody, 3], physics.subtree_com.clone()),
        p.f32("table", &[clip.data().len()], clip.data()),
        Arg::Struct(StructArg::TableLayout(shape.reference_layout())),
        p.i32("clip_offsets", &[clip.clips()], clip.offsets()),
        p.i32("end_effectors", &[ee.len()], ee),
        p.i32("tracked_bodies", &[tracked.len()], tracked),
        p.i32("clip_id", &[n], clip_id.clone()),
        p.f32("ref_time", &[n], ref_time.clone()),
        p.f32("actions", &[n, nu], actions.clone()),
        Arg::Struct(StructArg::Observation(params)),
        p.f32("obs", &[n, stride], nan_f32(n * stride)),
    ];
    p.launch(&OBSERVE, threads, args);

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let got = out.f32("obs");
        let per_env: Vec<Vec<Block>> = (0..n)
            .map(|e| {
                let tracked = (&clip, clip_id[e] as usize);
                reference_blocks(
                    tracked,
                    &layout,
                    &params,
                    &physics,
                    &actions,
                    ref_time[e],
                    e,
                )
            })
            .collect();
        let sizes: Vec<usize> = per_env[0].iter().map(|b| b.values.len()).collect();
        let total: usize = sizes.iter().sum();
        r.check(
            total == width,
            format!("the blocks fill observation_size = {width} values: {total}"),
        );
        let mut start = 0;
        for (k, size) in sizes.iter().enumerate() {
            let mut kernel = Vec::new();
            let mut expected = Vec::new();
            for (e, blocks) in per_env.iter().enumerate() {
                kernel.extend(wide(&got[e * stride + start..e * stride + start + size]));
                expected.extend(&blocks[k].values);
            }
            r.relative(&per_env[0][k].name, &kernel, &expected);
            for (name, columns) in &per_env[0][k].parts {
                let pick = |v: &[f64]| -> Vec<f64> {
                    (0..n)
                        .flat_map(|e| columns.iter().map(move |&c| v[e * size + c]))
                        .collect()
                };
                r.relative(name, &pick(&kernel), &pick(&expected));
            }
            start += size;
        }
        let pad = |v: &[f32]| -> Vec<f32> {
            (0..n)
                .flat_map(|e| v[e * stride + width..(e + 1) * stride].iter().copied())
                .collect()
        };
        r.bitwise_f32("padding after the row", &pad(got), &pad(p.input_f32("obs")));
        r
    })
}

pub fn checks(fx: &Fixture) -> Vec<Check> {
    let obs =
        |future_frames, future_spacing, prev_action, root_target, reference_bodies| ObsConfig {
            future_frames,
            future_spacing,
            prev_action,
            root_target,
            reference_bodies,
            ..ObsConfig::default()
        };
    vec![
        case(fx, 0, 64, ObsConfig::default(), 51),
        case(fx, 0, 48, obs(1, 2, false, true, false), 52),
        case(fx, 1, 48, obs(3, 1, true, true, false), 53),
        case(fx, 1, 48, obs(3, 2, false, false, false), 54),
        case(fx, 0, 48, obs(2, 2, true, true, false), 55),
        // The reference bodies after the root target, after the previous action, and last.
        case(fx, 0, 64, obs(2, 1, true, true, true), 56),
        case(fx, 1, 48, obs(1, 1, true, false, true), 57),
        case(fx, 0, 48, obs(0, 1, false, false, true), 58),
        // A library: every env its clip.
        case(fx, 2, 96, obs(3, 2, true, true, true), 59),
    ]
}
