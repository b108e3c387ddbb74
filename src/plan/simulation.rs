//! [`Simulation`]: MuJoCo Warp physics for `nworld` worlds, replayed from plans.
//!
//! Loading a plan allocates its memory regions and uploads their initial contents. Regions
//! bound to a name (every Model and Data array: `m.body_pos`, `d.qpos`, `d.efc.J`, ...) are
//! shared by name across the plans of one simulation, so the `kinematics` plan reads the state
//! the `step` plan writes. The first plan to bind a name allocates it and provides its initial
//! contents; later plans must agree on its size. Unnamed regions (scratch, in-graph
//! allocations) are private to their plan. Each plan is prepared once (see [`super::replay`])
//! and captured into its own CUDA graph.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;

use thiserror::Error;
use zerocopy::{FromBytes, Immutable, IntoBytes};

use crate::cuda::{
    CudaError, DeviceMemory, Function, Gpu, Graph, Module, PinnedHostMemory, Stream,
};

use super::error::PlanError;
use super::format::DeviceType;
use super::model::{Plan, PlanInfo};
use super::replay::{Prepared, ReplayContext, ReplayOrder, prepare_ops, record_ops};
use super::store::PlanStore;

/// Errors of loading and running plans on a GPU.
#[derive(Debug, Error)]
pub enum SimulationError {
    #[error(transparent)]
    Plan(#[from] PlanError),
    #[error(transparent)]
    Cuda(#[from] CudaError),
    #[error("plan `{plan}`: {problem}")]
    Incompatible { plan: String, problem: String },
    #[error(
        "no buffer named `{name}` (names look like `d.qpos` or `m.body_pos`; `instantmimic plan inspect` lists them)"
    )]
    NoBuffer { name: String },
    #[error("buffer `{name}` has {bytes} bytes, not a whole number of {elem}-byte elements")]
    BufferElement {
        name: String,
        bytes: usize,
        elem: usize,
    },
    #[error("buffer `{name}` holds {len} elements; writing {count} at {offset} does not fit")]
    BufferRange {
        name: String,
        len: usize,
        offset: usize,
        count: usize,
    },
    #[error("no plan `{0}` is loaded in this simulation")]
    NoPlan(String),
}

/// A plan ready to run: its prepared operations, its graph and what they point into.
struct LoadedPlan {
    info: Option<PlanInfo>,
    ops: Vec<Prepared>,
    pinned: Vec<Arc<PinnedHostMemory>>,
    graph: Graph,
    /// Every region's memory (shared named ones included), kept alive as long as the graph.
    _regions: Vec<Arc<DeviceMemory>>,
}

/// Physics for `nworld` worlds: shared named buffers and the loaded plans.
pub struct Simulation {
    gpu: Gpu,
    nworld: u32,
    named: BTreeMap<String, Arc<DeviceMemory>>,
    modules: HashMap<String, Module>,
    functions: HashMap<(String, String), Function>,
    plans: BTreeMap<String, LoadedPlan>,
    order: ReplayOrder,
}

/// A named device buffer viewed as elements of `T`: any type every bit pattern of which is a
/// value (`zerocopy`'s [`FromBytes`]: `f32`, `i32`, `u8`, arrays of them, ...), in the device's
/// (little-endian) byte order.
pub struct Buffer<'a, T: FromBytes + IntoBytes + Immutable + Copy> {
    name: &'a str,
    memory: &'a DeviceMemory,
    _t: std::marker::PhantomData<T>,
}

impl<T: FromBytes + IntoBytes + Immutable + Copy> Buffer<'_, T> {
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.memory.len() / size_of::<T>()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Copies the whole buffer to the host (waits for the simulation's stream).
    pub fn read(&self) -> Result<Vec<T>, SimulationError> {
        let mut values = vec![T::new_zeroed(); self.len()];
        self.memory.copy_to_host(0, values.as_mut_bytes())?;
        Ok(values)
    }

    /// Writes `values` at element `offset` (waits for the simulation's stream).
    pub fn write_at(&self, offset: usize, values: &[T]) -> Result<(), SimulationError> {
        if offset
            .checked_add(values.len())
            .is_none_or(|end| end > self.len())
        {
            return Err(SimulationError::BufferRange {
                name: self.name.to_string(),
                len: self.len(),
                offset,
                count: values.len(),
            });
        }
        self.memory
            .copy_from_host(offset * size_of::<T>(), values.as_bytes())?;
        Ok(())
    }

    /// Writes the whole buffer.
    pub fn write(&self, values: &[T]) -> Result<(), SimulationError> {
        if values.len() != self.len() {
            return Err(SimulationError::BufferRange {
                name: self.name.to_string(),
                len: self.len(),
                offset: 0,
                count: values.len(),
            });
        }
        self.write_at(0, values)
    }
}

impl Simulation {
    /// Loads the plans `names` captured for `nworld` worlds from `store`, in order (the first
    /// provides the initial contents of shared buffers), and captures a graph for each.
    pub fn load(
        gpu: &Gpu,
        store: &PlanStore,
        nworld: u32,
        names: &[&str],
    ) -> Result<Simulation, SimulationError> {
        Simulation::load_with_order(gpu, store, nworld, names, ReplayOrder::default())
    }

    /// [`Simulation::load`] with the operation order of the graphs (see [`ReplayOrder`]).
    pub fn load_with_order(
        gpu: &Gpu,
        store: &PlanStore,
        nworld: u32,
        names: &[&str],
        order: ReplayOrder,
    ) -> Result<Simulation, SimulationError> {
        let mut sim = Simulation {
            order,
            gpu: gpu.clone(),
            nworld,
            named: BTreeMap::new(),
            modules: HashMap::new(),
            functions: HashMap::new(),
            plans: BTreeMap::new(),
        };
        let plans = names
            .iter()
            .map(|name| store.plan(name, nworld))
            .collect::<Result<Vec<_>, _>>()?;
        sim.preload_modules(store, &plans)?;
        for (name, plan) in names.iter().zip(plans) {
            sim.add_plan(name, plan, store)?;
        }
        Ok(sim)
    }

    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    pub fn nworld(&self) -> u32 {
        self.nworld
    }

    /// Names of the shared buffers.
    pub fn buffer_names(&self) -> impl Iterator<Item = &str> {
        self.named.keys().map(String::as_str)
    }

    /// The buffer bound to `name` (e.g. `d.qpos`), as elements of `T`.
    pub fn buffer<'a, T: FromBytes + IntoBytes + Immutable + Copy>(
        &'a self,
        name: &'a str,
    ) -> Result<Buffer<'a, T>, SimulationError> {
        let memory = self
            .named
            .get(name)
            .ok_or_else(|| SimulationError::NoBuffer {
                name: name.to_string(),
            })?;
        let elem = size_of::<T>();
        if elem == 0 || memory.len() % elem != 0 {
            return Err(SimulationError::BufferElement {
                name: name.to_string(),
                bytes: memory.len(),
                elem,
            });
        }
        Ok(Buffer {
            name,
            memory,
            _t: std::marker::PhantomData,
        })
    }

    /// The device memory bound to `name`, shared (kernels of our own read and write it).
    pub fn shared_buffer(&self, name: &str) -> Result<Arc<DeviceMemory>, SimulationError> {
        self.named
            .get(name)
            .cloned()
            .ok_or_else(|| SimulationError::NoBuffer {
                name: name.to_string(),
            })
    }

    /// The [`PlanInfo`] a loaded plan was packed with.
    pub fn plan_info(&self, plan: &str) -> Option<&PlanInfo> {
        self.plans.get(plan).and_then(|p| p.info.as_ref())
    }

    fn loaded(&self, plan: &str) -> Result<&LoadedPlan, SimulationError> {
        self.plans
            .get(plan)
            .ok_or_else(|| SimulationError::NoPlan(plan.to_string()))
    }

    /// Runs one replay of `plan` (its graph) on the GPU's stream. Asynchronous.
    pub fn run(&self, plan: &str) -> Result<(), SimulationError> {
        self.loaded(plan)?.graph.launch(self.gpu.stream())?;
        Ok(())
    }

    /// The plan's own CUDA graph.
    pub fn graph(&self, plan: &str) -> Result<&Graph, SimulationError> {
        Ok(&self.loaded(plan)?.graph)
    }

    /// Queues `plan`'s operations on `stream`, typically inside a larger capture (a rollout
    /// records the step plan once per substep). The simulation must outlive that graph. On a
    /// stream that is not capturing (a reset queued directly) it launches the plan's own graph:
    /// the DAG order and the conditional nodes exist only inside a capture.
    pub fn record(&self, plan: &str, stream: &Stream) -> Result<(), SimulationError> {
        let loaded = self.loaded(plan)?;
        if !stream.is_capturing()? {
            loaded.graph.launch(stream)?;
            return Ok(());
        }
        record_ops(&loaded.ops, stream, &loaded.pinned, self.order)?;
        Ok(())
    }

    fn function(
        &mut self,
        store: &PlanStore,
        file: &str,
        entry: &str,
    ) -> Result<Function, PlanError> {
        let key = (file.to_string(), entry.to_string());
        if let Some(f) = self.functions.get(&key) {
            return Ok(f.clone());
        }
        if !self.modules.contains_key(file) {
            let ptx = store.module_ptx(file)?;
            let module = self
                .gpu
                .load_ptx(file, &ptx)
                .map_err(|e| PlanError::Asset(format!("loading module {file}: {e}")))?;
            self.modules.insert(file.to_string(), module);
        }
        let f = self.modules[file]
            .function(entry)
            .map_err(|e| PlanError::Asset(format!("module {file}: {e}")))?;
        self.functions.insert(key, f.clone());
        Ok(f)
    }

    /// Readies every module `plans` name ([`Gpu::preload_ptx`]): on a machine whose JIT cache
    /// is empty, helper processes compile them at once instead of this one after the other.
    fn preload_modules(&self, store: &PlanStore, plans: &[Plan]) -> Result<(), SimulationError> {
        let files: std::collections::BTreeSet<&str> = plans
            .iter()
            .filter(|plan| plan.header.device == DeviceType::Cuda)
            .flat_map(|plan| plan.modules.iter().map(|m| m.binary_filename.as_str()))
            .collect();
        let texts = files
            .iter()
            .map(|file| Ok((*file, store.module_ptx(file)?)))
            .collect::<Result<Vec<_>, PlanError>>()?;
        let modules: Vec<(&str, &[u8])> = texts.iter().map(|(f, ptx)| (*f, &ptx[..])).collect();
        self.gpu
            .preload_ptx(&modules)
            .map_err(|e| PlanError::Asset(format!("loading the plans' modules: {e}")))?;
        Ok(())
    }

    fn add_plan(
        &mut self,
        name: &str,
        mut plan: Plan,
        store: &PlanStore,
    ) -> Result<(), SimulationError> {
        let incompatible = |problem: String| SimulationError::Incompatible {
            plan: name.to_string(),
            problem,
        };
        if plan.header.device != DeviceType::Cuda {
            return Err(incompatible(
                "it was captured on the CPU; plans must be captured on a CUDA device".into(),
            ));
        }
        if let Some(info) = plan.info()
            && info.nworld != self.nworld
        {
            return Err(incompatible(format!(
                "it was captured for {} worlds, not {}",
                info.nworld, self.nworld
            )));
        }
        if self.plans.contains_key(name) {
            return Err(incompatible("it is already loaded".into()));
        }

        // Names bound to each region of this plan.
        let mut names_of: HashMap<u32, Vec<String>> = HashMap::new();
        for b in &plan.bindings {
            names_of.entry(b.region).or_default().push(b.name.clone());
        }
        let mut memories: HashMap<u32, Arc<DeviceMemory>> = HashMap::new();
        for region in &mut plan.regions {
            let names = names_of.get(&region.id).map(Vec::as_slice).unwrap_or(&[]);
            let size = usize::try_from(region.size)
                .map_err(|_| incompatible(format!("region {} is too large", region.id)))?;
            let existing: Vec<&Arc<DeviceMemory>> =
                names.iter().filter_map(|n| self.named.get(n)).collect();
            let memory = match existing.first() {
                Some(&shared) => {
                    if existing.len() != names.len()
                        || existing.iter().any(|m| !Arc::ptr_eq(m, shared))
                    {
                        return Err(incompatible(format!(
                            "names {names:?} share one buffer in this plan but not in the \
                             plans loaded before it"
                        )));
                    }
                    if shared.len() != size {
                        return Err(incompatible(format!(
                            "it binds `{}` with {size} bytes, an earlier plan with {} bytes \
                             (plans of one simulation must come from one capture)",
                            names[0],
                            shared.len()
                        )));
                    }
                    shared.clone()
                }
                None => {
                    let memory = Arc::new(self.gpu.alloc_zeroed(size)?);
                    if let Some(data) = region.initial_data.take() {
                        memory.copy_from_host(0, &data)?;
                    }
                    for n in names {
                        self.named.insert(n.clone(), memory.clone());
                    }
                    memory
                }
            };
            // Initial bytes are uploaded (or superseded by the first plan's): free the host copy.
            region.initial_data = None;
            memories.insert(region.id, memory);
        }

        // Regions bound only to Model arrays: MuJoCo Warp never writes the model in a step.
        let read_only: HashSet<u32> = names_of
            .iter()
            .filter(|(_, names)| names.iter().all(|n| n.starts_with("m.")))
            .map(|(&id, _)| id)
            .collect();
        let (major, minor) = self.gpu.info().compute_capability;
        let gpu = self.gpu.clone();
        let mut pinned = Vec::new();
        let ops = {
            let mut loader = |file: &str, entry: &str| self.function(store, file, entry);
            let alloc_pinned = |bytes: usize| gpu.alloc_pinned(bytes);
            let mut ctx = ReplayContext {
                plan: &plan,
                device_arch: major * 10 + minor,
                regions: &memories,
                function: &mut loader,
                pinned: &mut pinned,
                alloc_pinned: &alloc_pinned,
                read_only: &read_only,
            };
            prepare_ops(&mut ctx, &plan.ops, "")?
        };
        let stream = self.gpu.stream();
        let order = self.order;
        let graph = stream.capture(|s| record_ops(&ops, s, &pinned, order))?;
        graph.upload(stream)?;
        self.plans.insert(
            name.to_string(),
            LoadedPlan {
                info: plan.info.take(),
                ops,
                pinned,
                graph,
                _regions: memories.into_values().collect(),
            },
        );
        Ok(())
    }
}
