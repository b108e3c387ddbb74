//! The Rust replay of the step plan against MuJoCo Warp itself (GPU; `--features gpu`).
//!
//! The references are MuJoCo Warp's own states, made on the GPU machine by
//! `kernels_py/physics_reference.py exact --nworld 32` (`tests/device/physics_reference.sh`) and
//! committed under `tests/fixtures/physics_reference/`: seeded initial states and MuJoCo Warp's
//! qpos/qvel after a few step counts, for the default physics (`default_32`, against the plans
//! built into the binary), the deterministic one (`deterministic_32`, written with
//! configs/physics/deterministic.toml, against `ptx/deterministic`) and the G1's (`g1_32`, with
//! configs/physics/g1.toml, against the G1's built-in plans). Tests run from the
//! repository root (cargo's working directory, and session.sh's on the device).
//! `INSTANTMIMIC_PHYSICS_REFERENCE=DIR` checks one other reference instead, with the plans of
//! `INSTANTMIMIC_ASSETS` (a directory laid out like ptx/; default: the built-in plans).
//!
//! Both replay orders are checked (Warp's chain and our dependency DAG). With contacts, the
//! default physics differs from itself run to run (contacts, constraint rows and some solver
//! sums are collected with atomics): the reference records the largest difference among three
//! MuJoCo Warp runs from the same state. Where that spread is zero (the humanoid's free fall, no
//! contact) the replay must agree bit for bit; elsewhere, after one step, within 1e-5 or twice
//! the spread (the G1 collides with itself even in free fall). The deterministic variant must
//! agree bit for bit at every checkpoint, contacts or not.
#![cfg(feature = "gpu")]

mod skip_support;

use std::path::{Path, PathBuf};

use instantmimic::cuda::Gpu;
use instantmimic::env::{
    BodyModel, DeviceBodyModel, PhysicsSizes, PhysicsState, PhysicsStateError,
};
use instantmimic::kernels::{DeviceArray, EnvKernels};
use instantmimic::motion::Character;
use instantmimic::plan::{PhysicsOverflow, PlanStore, ReplayOrder, Simulation};

fn read_f32(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        bytes.len() % 4,
        0,
        "{}: not a whole number of f32",
        path.display()
    );
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> (f32, usize) {
    assert_eq!(a.len(), b.len());
    let mut worst = (0.0f32, 0usize);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let d = (x - y).abs();
        if d.is_nan() {
            return (f32::NAN, i);
        }
        if d > worst.0 {
            worst = (d, i);
        }
    }
    worst
}

struct Reference {
    dir: PathBuf,
    /// The plans to replay.
    plans: PlanStore,
    /// The character the reference simulates (its `character` key; the humanoid before the key).
    character: Character,
    summary: serde_json::Value,
    nworld: u32,
}

impl Reference {
    fn load(dir: PathBuf, plans: PlanStore) -> Reference {
        let file = dir.join("reference.json");
        let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let summary: serde_json::Value =
            serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let nworld = summary["nworld"].as_u64().expect("nworld") as u32;
        let character = match summary["character"].as_str() {
            Some(name) => Character::find(name).unwrap_or_else(|e| panic!("{name}: {e}")),
            None => Character::humanoid().expect("the humanoid"),
        };
        Reference {
            dir,
            plans,
            character,
            summary,
            nworld,
        }
    }
}

/// `INSTANTMIMIC_PHYSICS_REFERENCE` alone when set, else both committed references.
fn references() -> Vec<Reference> {
    if let Some(dir) = std::env::var_os("INSTANTMIMIC_PHYSICS_REFERENCE").map(PathBuf::from) {
        let assets = std::env::var_os("INSTANTMIMIC_ASSETS").map(PathBuf::from);
        return vec![Reference::load(dir, PlanStore::new(assets.as_deref()))];
    }
    let fixtures = Path::new("tests/fixtures/physics_reference");
    vec![
        Reference::load(fixtures.join("default_32"), PlanStore::new(None)),
        Reference::load(
            fixtures.join("deterministic_32"),
            PlanStore::new(Some(Path::new("ptx/deterministic"))),
        ),
        Reference::load(fixtures.join("g1_32"), PlanStore::embedded("characters/g1")),
    ]
}

/// A simulation in a reference case's initial state.
fn load_case(gpu: &Gpu, r: &Reference, case: &serde_json::Value, order: ReplayOrder) -> Simulation {
    let sim = Simulation::load_with_order(gpu, &r.plans, r.nworld, &["step", "kinematics"], order)
        .unwrap_or_else(|e| panic!("loading plans: {e}"));
    for field in ["qpos", "qvel", "ctrl"] {
        let file = case["files"][format!("init_{field}")]
            .as_str()
            .expect("file");
        let values = read_f32(&r.dir.join(file));
        sim.buffer::<f32>(&format!("d.{field}"))
            .expect("buffer")
            .write(&values)
            .unwrap_or_else(|e| panic!("writing d.{field}: {e}"));
    }
    sim
}

#[test]
fn step_plan_matches_mujoco_warp() {
    let gpu = Gpu::open(0).expect("a GPU");
    let mut failures: Vec<String> = Vec::new();
    for r in references() {
        check_reference(&gpu, &r, &mut failures);
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Replays every case of `r` in both orders; pushes each disagreement onto `failures`.
fn check_reference(gpu: &Gpu, r: &Reference, failures: &mut Vec<String>) {
    let deterministic = r.summary["deterministic"].as_bool().unwrap_or(false);
    let variant = r.dir.display();
    for order in [ReplayOrder::Linear, ReplayOrder::Dag] {
        for case in r.summary["cases"].as_array().expect("cases") {
            let name = case["name"].as_str().expect("case name");
            let sim = load_case(gpu, r, case, order);
            let mut done = 0u64;
            for checkpoint in case["checkpoints"].as_array().expect("checkpoints") {
                let target = checkpoint["steps"].as_u64().expect("steps");
                while done < target {
                    sim.run("step").expect("step");
                    done += 1;
                }
                gpu.stream().synchronize().expect("synchronize");
                for field in ["qpos", "qvel"] {
                    let expected = read_f32(&r.dir.join(checkpoint[field].as_str().expect("file")));
                    let got = sim
                        .buffer::<f32>(&format!("d.{field}"))
                        .unwrap()
                        .read()
                        .unwrap();
                    let (diff, at) = max_abs_diff(&got, &expected);
                    let identical = got
                        .iter()
                        .zip(&expected)
                        .all(|(a, b)| a.to_bits() == b.to_bits());
                    let spread = checkpoint["warp_vs_warp"][field].as_f64().unwrap_or(0.0) as f32;
                    println!(
                        "{variant} {order:?} {name}: after {target} steps max |d{field}| = {diff:.3e} (world {}); bit-identical: {identical}; MuJoCo Warp against itself: {spread:.3e}",
                        at / (got.len() / r.nworld as usize).max(1)
                    );
                    // Where MuJoCo Warp agreed with itself bit for bit (no contact collected
                    // with atomics: the humanoid's free fall; the deterministic variant), the
                    // replay must too. The G1 touches itself in free fall.
                    if (spread == 0.0 || deterministic) && !identical {
                        failures.push(format!(
                            "{variant} {order:?} {name}: {field} after {target} steps differs from MuJoCo Warp (max {diff:e})"
                        ));
                    } else if target == 1 {
                        let limit = (2.0 * spread).max(1e-5);
                        if diff.is_nan() || diff > limit {
                            failures.push(format!(
                                "{variant} {order:?} {name}: max |d{field}| after 1 step is {diff:e} > {limit:e}"
                            ));
                        }
                    }
                }
            }
        }
    }
}

/// The DAG order treats Model arrays as read-only: check that stepping with contacts leaves
/// every `m.*` buffer unchanged.
#[test]
fn stepping_leaves_model_arrays_unchanged() {
    let gpu = Gpu::open(0).expect("a GPU");
    for r in references() {
        model_arrays_unchanged(&gpu, &r);
    }
}

fn model_arrays_unchanged(gpu: &Gpu, r: &Reference) {
    let case = &r.summary["cases"][0];
    let sim = load_case(gpu, r, case, ReplayOrder::Linear);
    let names: Vec<String> = sim
        .buffer_names()
        .filter(|n| n.starts_with("m."))
        .map(str::to_string)
        .collect();
    let before: Vec<Vec<u8>> = names
        .iter()
        .map(|n| sim.buffer::<u8>(n).unwrap().read().unwrap())
        .collect();
    for _ in 0..100 {
        sim.run("step").unwrap();
        sim.run("kinematics").unwrap();
    }
    for (name, old) in names.iter().zip(&before) {
        let now = sim.buffer::<u8>(name).unwrap().read().unwrap();
        assert!(&now == old, "{name} changed during 100 steps");
    }
    println!(
        "{}: {} model arrays unchanged after 100 steps with contacts",
        r.dir.display(),
        names.len()
    );
    // The capacities (nconmax, njmax) hold every contact and constraint row of these states;
    // only the solver's iteration limits may show up in the flags.
    let overflow = PhysicsOverflow::read(&sim).unwrap();
    println!("overflow flags after 100 steps: {overflow:?}");
    assert_eq!(overflow.worlds, r.nworld as usize);
    assert_eq!((overflow.constraint_rows, overflow.contacts), (0, 0));
}

/// The step and kinematics plans of the store's smallest world count (`INSTANTMIMIC_ASSETS`, else
/// the embedded ones), loaded on GPU 0; `None` (after a skip note) when the store has none.
fn smallest_step_and_kinematics() -> Option<(Simulation, u32)> {
    let assets = std::env::var_os("INSTANTMIMIC_ASSETS").map(PathBuf::from);
    let store = PlanStore::new(assets.as_deref());
    let Ok(manifest) = store.manifest() else {
        skip_support::skip("no plan manifest in the store");
        return None;
    };
    let Some(nworld) = manifest.plans.iter().map(|p| p.nworld).min() else {
        skip_support::skip("the manifest lists no plans");
        return None;
    };
    let gpu = Gpu::open(0).expect("a GPU");
    let sim = Simulation::load(&gpu, &store, nworld, &["step", "kinematics"]).expect("plans load");
    Some((sim, nworld))
}

#[test]
fn kinematics_plan_reads_the_state_the_step_plan_writes() {
    let Some((sim, nworld)) = smallest_step_and_kinematics() else {
        return;
    };
    // Raise every world's root by 1 m: after the kinematics plan, every body is 1 m higher.
    let qpos = sim.buffer::<f32>("d.qpos").unwrap();
    let before = {
        sim.run("kinematics").unwrap();
        sim.buffer::<f32>("d.xpos").unwrap().read().unwrap()
    };
    let mut q = qpos.read().unwrap();
    let nq = q.len() / nworld as usize;
    for w in 0..nworld as usize {
        q[w * nq + 2] += 1.0;
    }
    qpos.write(&q).unwrap();
    sim.run("kinematics").unwrap();
    let after = sim.buffer::<f32>("d.xpos").unwrap().read().unwrap();
    let nbody = after.len() / 3 / nworld as usize;
    let mut checked = 0;
    for w in 0..nworld as usize {
        for b in 1..nbody {
            let i = (w * nbody + b) * 3;
            let dz = after[i + 2] - before[i + 2];
            assert!(
                (dz - 1.0).abs() < 1e-5,
                "world {w} body {b}: z moved by {dz}, expected 1"
            );
            assert!((after[i] - before[i]).abs() < 1e-6);
            checked += 1;
        }
    }
    println!("kinematics plan moved all {checked} bodies by the root offset");
}

/// The humanoid's plans serve the humanoid and refuse the G1, naming both characters' sizes:
/// a character and the plans of another cannot be mixed.
#[test]
fn the_humanoids_plans_refuse_another_characters_state() {
    let Some((sim, nworld)) = smallest_step_and_kinematics() else {
        return;
    };
    let humanoid = Character::humanoid().expect("the humanoid");
    let sizes = PhysicsSizes::of(&humanoid);
    let physics = PhysicsState::view(&sim, sizes, humanoid.name()).expect("the humanoid's state");
    assert_eq!(physics.qpos.shape(), [nworld as usize, sizes.nq]);
    let g1 = Character::built_in("g1")
        .expect("the G1 is built in")
        .expect("the G1 loads");
    match PhysicsState::view(&sim, PhysicsSizes::of(&g1), g1.name()) {
        Err(e @ PhysicsStateError::OtherCharacter { .. }) => {
            let message = e.to_string();
            assert!(
                message.contains(&sizes.to_string())
                    && message.contains(&PhysicsSizes::of(&g1).to_string())
                    && message.contains("capture plans for g1"),
                "{message}"
            );
        }
        Err(e) => panic!("another error than the character's: {e}"),
        Ok(_) => panic!("the humanoid's plans served the G1"),
    }
}

/// `||a - b|| / ||b||` over the elements `keep` selects (indices into both).
fn relative_over(a: &[f32], b: &[f32], keep: impl Fn(usize) -> bool) -> f64 {
    let (mut diff, mut norm) = (0.0f64, 0.0f64);
    for i in (0..b.len()).filter(|&i| keep(i)) {
        let (x, y) = (f64::from(a[i]), f64::from(b[i]));
        if !x.is_finite() {
            return f64::INFINITY;
        }
        diff += (x - y) * (x - y);
        norm += y * y;
    }
    (diff / norm.max(1e-30)).sqrt()
}

/// `env.body_kinematics = "fused"`: the `body_kinematics` kernel against the kinematics plan
/// (MuJoCo Warp's `fwd_kinematics` and `com_vel`) on the same states, MuJoCo Warp's own from
/// the default reference's cases after their steps: `xpos`, `xquat`, `cvel` of bodies 1.. and
/// `subtree_com[:, 1]` within 1e-5 (relative, per array); after a reset only the envs marked
/// done are written, the others left as they were.
#[test]
fn body_kinematics_kernel_matches_the_kinematics_plan() {
    let gpu = Gpu::open(0).expect("a GPU");
    let kernels = EnvKernels::load(&gpu).expect("env kernels");
    let mut checked = 0;
    // The references of the default physics of each character (the humanoid's, the G1's).
    for r in references()
        .into_iter()
        .filter(|r| !r.summary["deterministic"].as_bool().unwrap_or(false))
    {
        checked += body_kinematics_matches(&gpu, &kernels, &r);
    }
    assert!(checked > 0, "no case in the references");
}

/// [`body_kinematics_kernel_matches_the_kinematics_plan`] on one reference: the number of
/// cases checked.
fn body_kinematics_matches(gpu: &Gpu, kernels: &EnvKernels, r: &Reference) -> usize {
    let character = &r.character;
    let model = DeviceBodyModel::upload(gpu, &BodyModel::for_character(character).unwrap())
        .expect("the body tables");
    let nbody = character.bodies().len();
    let n = r.nworld as usize;
    let mut checked = 0;
    for case in r.summary["cases"].as_array().expect("cases") {
        let sim = load_case(gpu, r, case, ReplayOrder::Dag);
        for _ in 0..5 {
            sim.run("step").expect("step");
        }
        sim.run("kinematics").expect("kinematics");
        gpu.stream().synchronize().unwrap();
        let fields = ["d.xpos", "d.xquat", "d.subtree_com", "d.cvel"];
        let read = |name: &str| sim.buffer::<f32>(name).unwrap().read().unwrap();
        let plan: Vec<Vec<f32>> = fields.iter().map(|f| read(f)).collect();
        let physics = PhysicsState::view(&sim, PhysicsSizes::of(character), character.name())
            .expect("the state buffers");
        // Even envs were reset (only_done): odd ones must keep what they hold (NaN here).
        let flags: Vec<i32> = (0..n).map(|e| i32::from(e % 2 == 0)).collect();
        let done = DeviceArray::from_slice(gpu, [n], &flags).unwrap();
        for only_done in [false, true] {
            for (f, values) in fields.iter().zip(&plan) {
                sim.buffer::<f32>(f)
                    .unwrap()
                    .write(&vec![f32::NAN; values.len()])
                    .unwrap();
            }
            model
                .record(kernels, gpu.stream(), n, &physics, &done, only_done)
                .expect("body_kinematics");
            gpu.stream().synchronize().unwrap();
            let name = case["name"].as_str().unwrap_or("?");
            for (f, expected) in fields.iter().zip(&plan) {
                let got = read(f);
                let width = expected.len() / n / nbody;
                let written = |i: usize| {
                    let (e, b) = (i / width / nbody, i / width % nbody);
                    let body = if *f == "d.subtree_com" {
                        b == 1
                    } else {
                        b >= 1
                    };
                    body && (!only_done || flags[e] != 0)
                };
                let error = relative_over(&got, expected, written);
                println!(
                    "{}: {name}, only_done {only_done}: {f} relative error {error:.2e}",
                    character.name()
                );
                assert!(error <= 1e-5, "{name}: {f} off the plan by {error:.2e}");
                if only_done {
                    let untouched = (0..got.len())
                        .filter(|&i| (i / width / nbody) % 2 == 1)
                        .all(|i| got[i].is_nan());
                    assert!(
                        untouched,
                        "{name}: {f} written for an env that was not reset"
                    );
                }
            }
            checked += 1;
        }
    }
    checked
}
