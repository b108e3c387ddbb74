//! Where plans and their PTX come from: the copies embedded in the binary at build time, or a
//! directory with the same layout as the repository's `ptx/` (for plans captured by a user, e.g.
//! for another world count or another character):
//!
//! ```text
//! plans/manifest.json      the captured plans: name, world count, file, modules
//! plans/<name>_<N>.wrp.zst a packed plan (a raw .wrp is accepted too)
//! mjwarp/<module>.ptx      the PTX of each MuJoCo Warp module, named as the plan records it
//! ```
//!
//! The embedded files hold one such layout per built-in character: the default character's at
//! the root of `ptx/`, every other one's under `ptx/characters/<name>/` ([`PlanStore::embedded`]
//! takes that root). A plan set simulates one model: its manifest records the MJCF it was
//! captured from and the model's sizes ([`SimulatedModel`]), which a run compares with its
//! character before it loads a plan.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use serde::Deserialize;

use super::error::PlanError;
use super::model::Plan;
use super::pack::load_plan;
use super::prefetch::PrefetchedPlans;

/// Directory of MuJoCo Warp module PTX, relative to the store's root.
pub const MJWARP_PTX_DIR: &str = "mjwarp";
/// Directory of the plans, relative to the store's root.
pub const PLANS_DIR: &str = "plans";
/// Where the embedded plans of the built-in characters other than the default are, relative to
/// `ptx/`: `characters/<name>/plans/...`, `characters/<name>/mjwarp/...`.
pub const EMBEDDED_CHARACTERS_DIR: &str = "characters";
/// The plan manifest, relative to the store's root.
pub const MANIFEST_PATH: &str = "plans/manifest.json";

/// MuJoCo Warp's step with the physics options of the plan set's manifest: the evaluation's, and
/// every other simulation's but the training rollout's (`kernels_py/physics.py` PLAN_NAMES).
pub const STEP_PLAN: &str = "step";
/// The step captured with the manifest's training solver iterations (`training_iterations`,
/// `training_ls_iterations`): fewer Newton and line-search iterations, for the training
/// rollouts only (`env.training_solver`). A plan set captured without them has none.
pub const TRAINING_STEP_PLAN: &str = "training_step";
/// The kinematics a reset needs before observations are built.
pub const KINEMATICS_PLAN: &str = "kinematics";

/// `plans/manifest.json`, as `kernels_py/capture.py` writes it.
#[derive(Clone, Debug, Deserialize)]
pub struct PlanManifest {
    pub format: u32,
    /// warp-lang version that captured the plans.
    pub warp: String,
    /// Physics options and model sizes the plans were captured with.
    pub physics: serde_json::Value,
    pub plans: Vec<PlanEntry>,
}

/// The model a plan set simulates, as its manifest's `physics` records it (`config.character`,
/// the simulation MJCF, and the compiled sizes), or as a character's description states it.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, Deserialize)]
pub struct SimulatedModel {
    /// The simulation MJCF, as the build step names it (e.g. `configs/characters/g1.xml`).
    pub mjcf: String,
    pub nq: usize,
    pub nv: usize,
    /// Actuators.
    pub nu: usize,
    /// Bodies, the world included.
    pub nbody: usize,
}

impl SimulatedModel {
    /// The model recorded by a manifest's (or a packed plan's) `physics` object; `None` when
    /// a field is missing (plans captured before the manifest recorded them).
    pub fn from_physics(
        physics: &serde_json::Map<String, serde_json::Value>,
    ) -> Option<SimulatedModel> {
        let size = |key: &str| {
            physics
                .get(key)
                .and_then(serde_json::Value::as_u64)
                .and_then(|n| usize::try_from(n).ok())
        };
        Some(SimulatedModel {
            mjcf: physics
                .get("config")
                .and_then(|c| c.get("character"))
                .and_then(serde_json::Value::as_str)?
                .to_string(),
            nq: size("nq")?,
            nv: size("nv")?,
            nu: size("nu")?,
            nbody: size("nbody")?,
        })
    }

    /// `configs/characters/g1.xml (nq 36, nv 35, nu 29, nbody 31)`.
    pub fn describe(&self) -> String {
        format!(
            "{} (nq {}, nv {}, nu {}, nbody {})",
            self.mjcf, self.nq, self.nv, self.nu, self.nbody
        )
    }
}

/// One captured plan.
#[derive(Clone, Debug, Deserialize)]
pub struct PlanEntry {
    pub name: String,
    pub nworld: u32,
    /// File name under `plans/`.
    pub file: String,
}

/// Where a store's files come from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PlanSource {
    /// The files built into the binary under `root` (relative to `ptx/`; empty: its top, the
    /// default character's plans; else e.g. `characters/g1`).
    Embedded { root: String },
    /// A directory laid out like `ptx/` (`--assets`, a character directory).
    Directory(PathBuf),
}

/// Embedded assets or a directory. A store made with [`PlanStore::keeping_decoded`] also keeps
/// the plans it has decoded: an HPO runner trains trial after trial from one store, and its
/// trials then share one decoding of each plan. A plain store keeps nothing, so a training run
/// does not hold the plans' initial bytes (~70 MB per 4096-world plan) on the host once they
/// are uploaded. Clones share what was kept.
#[derive(Clone, Debug)]
pub struct PlanStore {
    source: PlanSource,
    decoded: Option<Arc<Mutex<DecodedPlans>>>,
    /// Plans being decoded ahead of their use ([`PlanStore::prefetching`]).
    prefetched: Option<Arc<PrefetchedPlans>>,
}

/// Decoded plans by name and world count.
type DecodedPlans = HashMap<(String, u32), Plan>;

impl PlanStore {
    /// The default character's embedded plans, or `dir` when given.
    pub fn new(dir: Option<&Path>) -> PlanStore {
        match dir {
            Some(dir) => PlanStore::from_source(PlanSource::Directory(dir.to_path_buf())),
            None => PlanStore::embedded(""),
        }
    }

    /// The plans built into the binary under `root` (relative to `ptx/`, e.g. `characters/g1`;
    /// empty: the default character's).
    pub fn embedded(root: &str) -> PlanStore {
        PlanStore::from_source(PlanSource::Embedded {
            root: root.trim_matches('/').to_string(),
        })
    }

    /// The plans of `source`.
    pub fn from_source(source: PlanSource) -> PlanStore {
        PlanStore {
            source,
            decoded: None,
            prefetched: None,
        }
    }

    /// This store, keeping every plan it decodes from now on.
    pub fn keeping_decoded(self) -> PlanStore {
        PlanStore {
            decoded: Some(Arc::default()),
            ..self
        }
    }

    /// This store, with each of `plans` (name, world count) being decoded on a thread of its
    /// own from now on: [`PlanStore::inspect_plan`] waits for one and looks at it in place, and
    /// the first [`PlanStore::plan`] for it takes it. A plan the manifest does not list is left
    /// to that request, which says so.
    pub fn prefetching(self, plans: &[(&str, u32)]) -> PlanStore {
        let prefetched = self.prefetched.clone().unwrap_or_default();
        let listed = self.manifest().map(|m| m.plans).unwrap_or_default();
        for &(name, nworld) in plans {
            if !listed.iter().any(|p| p.name == name && p.nworld == nworld) {
                continue;
            }
            let plain = PlanStore::from_source(self.source.clone());
            let owned = name.to_owned();
            prefetched.start(name, nworld, move || plain.decode(&owned, nworld));
        }
        PlanStore {
            prefetched: Some(prefetched),
            ..self
        }
    }

    /// `inspect` on the plan `name` for `nworld` worlds: a prefetched plan stays for the
    /// simulation that loads it; any other is decoded for this look and dropped.
    pub fn inspect_plan<T>(
        &self,
        name: &str,
        nworld: u32,
        inspect: impl FnOnce(&Plan) -> T,
    ) -> Result<T, PlanError> {
        let inspect = match &self.prefetched {
            Some(prefetched) => match prefetched.inspect(name, nworld, inspect) {
                Ok(looked) => return looked,
                Err(inspect) => inspect,
            },
            None => inspect,
        };
        Ok(inspect(&self.plan(name, nworld)?))
    }

    pub fn source(&self) -> &PlanSource {
        &self.source
    }

    /// Where the plans are, for messages: `the plans built into this binary` (`... under
    /// characters/g1`), or the directory.
    pub fn describe(&self) -> String {
        match &self.source {
            PlanSource::Embedded { root } if root.is_empty() => {
                "the plans built into this binary".to_string()
            }
            PlanSource::Embedded { root } => {
                format!("the plans built into this binary under {root}/")
            }
            PlanSource::Directory(dir) => dir.display().to_string(),
        }
    }

    /// A file by its path relative to the store's root.
    pub fn read(&self, rel: &str) -> Result<Cow<'static, [u8]>, PlanError> {
        match &self.source {
            PlanSource::Embedded { root } => {
                let path = if root.is_empty() {
                    rel.to_string()
                } else {
                    format!("{root}/{rel}")
                };
                crate::assets::get(&path).map(Cow::Borrowed).ok_or_else(|| {
                    PlanError::Asset(format!("{path} is not built into this binary"))
                })
            }
            PlanSource::Directory(dir) => {
                let path = dir.join(rel);
                std::fs::read(&path)
                    .map(Cow::Owned)
                    .map_err(|e| PlanError::Asset(format!("{}: {e}", path.display())))
            }
        }
    }

    /// The plan manifest.
    pub fn manifest(&self) -> Result<PlanManifest, PlanError> {
        let bytes = self.read(MANIFEST_PATH)?;
        serde_json::from_slice(&bytes).map_err(|e| {
            PlanError::Asset(format!(
                "{MANIFEST_PATH} in {}: not a plan manifest: {e}",
                self.describe()
            ))
        })
    }

    /// The model the store's plans simulate, as its manifest records it.
    pub fn model(&self) -> Result<SimulatedModel, PlanError> {
        let manifest = self.manifest()?;
        let physics = manifest.physics.as_object();
        physics.and_then(SimulatedModel::from_physics).ok_or_else(|| {
            PlanError::Asset(format!(
                "{MANIFEST_PATH} in {} records no model (physics.config.character, nq, nv, nu, nbody): recapture the plans with kernels_py/capture.py",
                self.describe()
            ))
        })
    }

    /// Whether the manifest lists a `name` plan for `nworld` worlds.
    pub fn has_plan(&self, name: &str, nworld: u32) -> Result<bool, PlanError> {
        Ok(self
            .manifest()?
            .plans
            .iter()
            .any(|p| p.name == name && p.nworld == nworld))
    }

    /// The plan `name` captured for `nworld` worlds (kept after the first request when the
    /// store keeps decoded plans: a directory's plan file is then read once).
    pub fn plan(&self, name: &str, nworld: u32) -> Result<Plan, PlanError> {
        let Some(decoded) = &self.decoded else {
            return self.take_or_decode(name, nworld);
        };
        let key = (name.to_string(), nworld);
        // A poisoned lock only means another thread panicked while inserting: decode again.
        if let Some(plan) = decoded.lock().ok().and_then(|d| d.get(&key).cloned()) {
            return Ok(plan);
        }
        let plan = self.take_or_decode(name, nworld)?;
        if let Ok(mut decoded) = decoded.lock() {
            decoded.insert(key, plan.clone());
        }
        Ok(plan)
    }

    /// The prefetched plan, taken out, else the plan decoded now.
    fn take_or_decode(&self, name: &str, nworld: u32) -> Result<Plan, PlanError> {
        match self.prefetched.as_ref().and_then(|p| p.take(name, nworld)) {
            Some(plan) => plan,
            None => self.decode(name, nworld),
        }
    }

    fn decode(&self, name: &str, nworld: u32) -> Result<Plan, PlanError> {
        let manifest = self.manifest()?;
        let entry = manifest
            .plans
            .iter()
            .find(|p| p.name == name && p.nworld == nworld)
            .ok_or_else(|| {
                let mut have: Vec<String> = manifest
                    .plans
                    .iter()
                    .filter(|p| p.name == name)
                    .map(|p| p.nworld.to_string())
                    .collect();
                have.dedup();
                PlanError::Asset(format!(
                    "no `{name}` plan for {nworld} worlds in {} (it has {}); capture one with \
                     kernels_py/capture.py --nworld {nworld} on a GPU and pass its directory with --assets",
                    self.describe(),
                    if have.is_empty() {
                        "none".to_string()
                    } else {
                        format!("{} worlds", have.join(", "))
                    }
                ))
            })?;
        if entry.file.contains('/') || entry.file.contains("..") {
            return Err(PlanError::Asset(format!(
                "plan file name {:?} in the manifest must be a plain file name",
                entry.file
            )));
        }
        let rel = format!("{PLANS_DIR}/{}", entry.file);
        let bytes = self.read(&rel)?;
        load_plan(&bytes).map_err(|e| PlanError::Asset(format!("{rel}: {e}")))
    }

    /// The PTX of a MuJoCo Warp module, by the binary file name a plan records (e.g.
    /// `wp_smooth_0b7e74a.sm90.cubin`: the capture ran Warp's own CUBIN path). One PTX serves
    /// every arch, so files are named without the arch: `mjwarp/wp_smooth_0b7e74a.ptx`.
    pub fn module_ptx(&self, binary_filename: &str) -> Result<Cow<'static, [u8]>, PlanError> {
        let file = ptx_file_name(binary_filename)?;
        self.read(&format!("{MJWARP_PTX_DIR}/{file}")).map_err(|e| {
            PlanError::Asset(format!(
                "{e} (regenerate ptx/ with kernels_py/compile.py after capturing plans)"
            ))
        })
    }
}

/// The `mjwarp/` file name of a module binary name: `<stem>.sm<NN>[a|f].<ptx|cubin>` ->
/// `<stem>.ptx` (kernels_py/physics.py `ptx_file_name` does the same).
pub fn ptx_file_name(binary_filename: &str) -> Result<String, PlanError> {
    let bad = || {
        PlanError::Asset(format!(
            "unexpected module binary name {binary_filename:?} (expected <module>.sm<arch>.ptx or .cubin)"
        ))
    };
    if binary_filename.contains('/') || binary_filename.contains("..") {
        return Err(bad());
    }
    let stem = binary_filename
        .strip_suffix(".ptx")
        .or_else(|| binary_filename.strip_suffix(".cubin"))
        .ok_or_else(bad)?;
    let (stem, arch) = stem.rsplit_once(".sm").ok_or_else(bad)?;
    let digits = arch.trim_end_matches(['a', 'f']);
    if stem.is_empty() || digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad());
    }
    Ok(format!("{stem}.ptx"))
}

#[cfg(test)]
mod tests {
    use super::{KINEMATICS_PLAN, PlanStore, STEP_PLAN, ptx_file_name};

    #[test]
    fn a_prefetched_plan_is_inspected_in_place_then_handed_over_once() {
        let plain = PlanStore::new(None);
        let decoded = plain
            .plan(KINEMATICS_PLAN, 32)
            .expect("the kinematics plan for 32");
        let store = PlanStore::new(None).prefetching(&[
            (KINEMATICS_PLAN, 32),
            // Not in the manifest: left to the request, which says so.
            (STEP_PLAN, 3),
        ]);
        let looked = store
            .inspect_plan(KINEMATICS_PLAN, 32, |p| (p.modules.len(), p.regions.len()))
            .expect("inspected");
        assert_eq!(looked, (decoded.modules.len(), decoded.regions.len()));
        // Still there after the look: the simulation takes the same plan.
        assert_eq!(store.plan(KINEMATICS_PLAN, 32).expect("taken"), decoded);
        // Taken once; a second request decodes it again, to the same plan.
        assert_eq!(store.plan(KINEMATICS_PLAN, 32).expect("decoded"), decoded);
        let missing = store.plan(STEP_PLAN, 3).expect_err("no plan for 3 worlds");
        assert!(
            missing.to_string().contains("no `step` plan for 3 worlds"),
            "{missing}"
        );
        let missing = store
            .inspect_plan(STEP_PLAN, 3, |_| ())
            .expect_err("no plan for 3 worlds");
        assert!(
            missing.to_string().contains("no `step` plan for 3 worlds"),
            "{missing}"
        );
    }

    #[test]
    fn module_binary_names_map_to_arch_free_ptx_names() {
        for (binary, ptx) in [
            (
                "wp_mujoco_warp._src.smooth_0b7e74a.sm90.cubin",
                "wp_mujoco_warp._src.smooth_0b7e74a.ptx",
            ),
            (
                "wp__k__locals__kernel_5_6622bd1.sm80.ptx",
                "wp__k__locals__kernel_5_6622bd1.ptx",
            ),
            ("wp_a_1234567.sm90a.cubin", "wp_a_1234567.ptx"),
        ] {
            assert_eq!(ptx_file_name(binary).unwrap(), ptx);
        }
        for bad in [
            "wp_a.cubin",
            "wp_a.smx.ptx",
            "../x.sm80.ptx",
            "wp_a.sm80.o",
            ".sm80.ptx",
        ] {
            assert!(ptx_file_name(bad).is_err(), "{bad} accepted");
        }
    }
}
