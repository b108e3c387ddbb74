//! What a kernel check runs: a program of named host buffers and steps (kernel launches, element
//! copies), executed either by Warp on the CPU (`kernels_py/checks/run_kernel.py`, [`super::cpu`])
//! or by the generated launchers on a GPU (`tests/gpu_env_kernels.rs`). Both executions take the
//! same [`Program`] and give back the same [`Outputs`], which the f64 references then judge.

use std::collections::BTreeMap;

use instantmimic::kernels::manifest::{EnvManifest, SlotType};
use instantmimic::kernels::{
    GoalParams, KernelAbi, MANIFEST_ASSET, ObservationParams, ParamKind, ReferenceLayout,
    ResetParams, ScalarType, TrackingParams, Yardstick,
};

/// Values of a buffer, row-major.
#[derive(Clone, Debug, PartialEq)]
pub enum HostData {
    F32(Vec<f32>),
    F64(Vec<f64>),
    I32(Vec<i32>),
}

impl HostData {
    pub fn scalar(&self) -> ScalarType {
        match self {
            HostData::F32(_) => ScalarType::Float32,
            HostData::F64(_) => ScalarType::Float64,
            HostData::I32(_) => ScalarType::Int32,
        }
    }

    pub fn dtype_name(&self) -> &'static str {
        match self {
            HostData::F32(_) => "float32",
            HostData::F64(_) => "float64",
            HostData::I32(_) => "int32",
        }
    }

    pub fn len(&self) -> usize {
        match self {
            HostData::F32(v) => v.len(),
            HostData::F64(v) => v.len(),
            HostData::I32(v) => v.len(),
        }
    }

    /// Little-endian bytes, as the `.bin` files and device memory hold them.
    pub fn to_le_bytes(&self) -> Vec<u8> {
        match self {
            HostData::F32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            HostData::F64(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            HostData::I32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }

    /// Values of `like`'s type from little-endian bytes (`None` if the length does not fit).
    pub fn from_le_bytes(like: &HostData, bytes: &[u8]) -> Option<HostData> {
        let size = like.scalar().size();
        if bytes.len() != like.len() * size {
            return None;
        }
        let chunks = bytes.chunks_exact(size);
        Some(match like {
            HostData::F32(_) => HostData::F32(
                chunks
                    .map(|c| f32::from_le_bytes(c.try_into().unwrap_or_default()))
                    .collect(),
            ),
            HostData::F64(_) => HostData::F64(
                chunks
                    .map(|c| f64::from_le_bytes(c.try_into().unwrap_or_default()))
                    .collect(),
            ),
            HostData::I32(_) => HostData::I32(
                chunks
                    .map(|c| i32::from_le_bytes(c.try_into().unwrap_or_default()))
                    .collect(),
            ),
        })
    }
}

/// A named buffer of a program: its shape and initial values.
#[derive(Clone, Debug)]
pub struct Buffer {
    pub name: String,
    pub shape: Vec<usize>,
    pub data: HostData,
}

/// A scalar kernel argument.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scalar {
    F32(f32),
    F64(f64),
    I32(i32),
}

impl Scalar {
    pub fn scalar(self) -> ScalarType {
        match self {
            Scalar::F32(_) => ScalarType::Float32,
            Scalar::F64(_) => ScalarType::Float64,
            Scalar::I32(_) => ScalarType::Int32,
        }
    }

    pub fn dtype_name(self) -> &'static str {
        match self {
            Scalar::F32(_) => "float32",
            Scalar::F64(_) => "float64",
            Scalar::I32(_) => "int32",
        }
    }

    /// The value as JSON (f32 widened to f64 exactly, so Python reads back the same f32).
    pub fn json_value(self) -> serde_json::Value {
        match self {
            Scalar::F32(v) => serde_json::json!(f64::from(v)),
            Scalar::F64(v) => serde_json::json!(v),
            Scalar::I32(v) => serde_json::json!(v),
        }
    }
}

/// A `@wp.struct` argument, as the generated Rust struct (which the GPU launchers take).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StructArg {
    Tracking(TrackingParams),
    Reset(ResetParams),
    Observation(ObservationParams),
    Yardstick(Yardstick),
    Goal(GoalParams),
    /// The reference table's row layout (`ReferenceLayout`).
    TableLayout(ReferenceLayout),
}

impl StructArg {
    pub fn name(&self) -> &'static str {
        match self {
            StructArg::Tracking(_) => "TrackingParams",
            StructArg::Reset(_) => "ResetParams",
            StructArg::Observation(_) => "ObservationParams",
            StructArg::Yardstick(_) => "Yardstick",
            StructArg::Goal(_) => "GoalParams",
            StructArg::TableLayout(_) => "ReferenceLayout",
        }
    }

    /// The fields in declaration order, for Python's field dict.
    pub fn fields(&self) -> Vec<(&'static str, Scalar)> {
        use Scalar::{F32, I32};
        match *self {
            StructArg::Tracking(p) => vec![
                ("pose_weight", F32(p.pose_weight)),
                ("velocity_weight", F32(p.velocity_weight)),
                ("com_weight", F32(p.com_weight)),
                ("ee_pos_weight", F32(p.ee_pos_weight)),
                ("ee_rot_weight", F32(p.ee_rot_weight)),
                ("dt", F32(p.dt)),
                ("termination_height", F32(p.termination_height)),
                ("tracking_distance", F32(p.tracking_distance)),
                ("min_root_height", F32(p.min_root_height)),
                ("min_reward", F32(p.min_reward)),
                ("mean_tracking_distance", F32(p.mean_tracking_distance)),
                ("grace_steps", I32(p.grace_steps)),
                ("max_episode_steps", I32(p.max_episode_steps)),
                ("ee_relative", I32(p.ee_relative)),
            ],
            StructArg::Reset(p) => vec![
                ("seed", I32(p.seed)),
                ("horizon", I32(p.horizon)),
                ("dt", F32(p.dt)),
                ("noise_std", F32(p.noise_std)),
                ("start_time", F32(p.start_time)),
            ],
            StructArg::Observation(p) => vec![
                ("future_frames", I32(p.future_frames)),
                ("future_spacing", I32(p.future_spacing)),
                ("dt", F32(p.dt)),
                ("prev_action", I32(p.prev_action)),
                ("root_target", I32(p.root_target)),
                ("reference_bodies", I32(p.reference_bodies)),
            ],
            StructArg::Yardstick(p) => vec![
                ("max_body_distance", F32(p.max_body_distance)),
                ("max_root_drop", F32(p.max_root_drop)),
                (
                    "robotics_max_anchor_height",
                    F32(p.robotics_max_anchor_height),
                ),
                ("robotics_max_anchor_tilt", F32(p.robotics_max_anchor_tilt)),
                (
                    "robotics_max_end_effector_height",
                    F32(p.robotics_max_end_effector_height),
                ),
            ],
            StructArg::Goal(p) => vec![
                ("seed", I32(p.seed)),
                ("horizon", I32(p.horizon)),
                ("min_distance", F32(p.min_distance)),
                ("max_distance", F32(p.max_distance)),
                ("reach_radius", F32(p.reach_radius)),
                ("progress_weight", F32(p.progress_weight)),
                ("bonus_weight", F32(p.bonus_weight)),
                ("fall_height", F32(p.fall_height)),
                ("max_episode_steps", I32(p.max_episode_steps)),
            ],
            StructArg::TableLayout(l) => vec![
                ("qvel", I32(l.qvel)),
                ("body_pos", I32(l.body_pos)),
                ("body_quat", I32(l.body_quat)),
                ("body_linvel", I32(l.body_linvel)),
                ("body_angvel", I32(l.body_angvel)),
                ("com_pos", I32(l.com_pos)),
                ("com_vel", I32(l.com_vel)),
                ("heading", I32(l.heading)),
                ("stride", I32(l.stride)),
                ("bodies", I32(l.bodies)),
            ],
        }
    }
}

/// One kernel argument.
#[derive(Clone, Debug)]
pub enum Arg {
    /// A buffer of the program, by name.
    Buffer(String),
    Scalar(Scalar),
    Struct(StructArg),
}

/// One step of a program.
#[derive(Clone, Debug)]
pub enum Step {
    /// A launch over `dim` threads with `args` in the kernel's parameter order.
    Launch {
        abi: &'static KernelAbi,
        dim: usize,
        args: Vec<Arg>,
    },
    /// `dst[dst_offset..][..count] = src[src_offset..][..count]` (flat elements), what the
    /// rollout does with `Stream::copy` between launches.
    Copy {
        src: String,
        src_offset: usize,
        dst: String,
        dst_offset: usize,
        count: usize,
    },
}

/// Buffers and steps; see the module documentation.
#[derive(Clone, Debug)]
pub struct Program {
    /// What the case is, for messages.
    pub name: String,
    pub buffers: Vec<Buffer>,
    pub steps: Vec<Step>,
}

/// Every buffer after the last step.
#[derive(Clone, Debug, Default)]
pub struct Outputs {
    pub buffers: BTreeMap<String, HostData>,
}

impl Outputs {
    fn get(&self, name: &str) -> &HostData {
        self.buffers
            .get(name)
            .unwrap_or_else(|| panic!("the execution returned no buffer {name}"))
    }

    pub fn f32(&self, name: &str) -> &[f32] {
        match self.get(name) {
            HostData::F32(v) => v,
            other => panic!("buffer {name} is {}, not float32", other.dtype_name()),
        }
    }

    pub fn f64(&self, name: &str) -> &[f64] {
        match self.get(name) {
            HostData::F64(v) => v,
            other => panic!("buffer {name} is {}, not float64", other.dtype_name()),
        }
    }

    pub fn i32(&self, name: &str) -> &[i32] {
        match self.get(name) {
            HostData::I32(v) => v,
            other => panic!("buffer {name} is {}, not int32", other.dtype_name()),
        }
    }
}

impl Program {
    pub fn new(name: impl Into<String>) -> Program {
        Program {
            name: name.into(),
            buffers: Vec::new(),
            steps: Vec::new(),
        }
    }

    fn add(&mut self, name: &str, shape: &[usize], data: HostData) -> Arg {
        assert_eq!(
            shape.iter().product::<usize>(),
            data.len(),
            "{}: buffer {name} of shape {shape:?} holds {} values",
            self.name,
            data.len()
        );
        assert!(
            self.buffers.iter().all(|b| b.name != name),
            "{}: buffer {name} added twice",
            self.name
        );
        self.buffers.push(Buffer {
            name: name.to_owned(),
            shape: shape.to_vec(),
            data,
        });
        Arg::Buffer(name.to_owned())
    }

    pub fn f32(&mut self, name: &str, shape: &[usize], data: Vec<f32>) -> Arg {
        self.add(name, shape, HostData::F32(data))
    }

    pub fn f64(&mut self, name: &str, shape: &[usize], data: Vec<f64>) -> Arg {
        self.add(name, shape, HostData::F64(data))
    }

    pub fn i32(&mut self, name: &str, shape: &[usize], data: Vec<i32>) -> Arg {
        self.add(name, shape, HostData::I32(data))
    }

    pub fn launch(&mut self, abi: &'static KernelAbi, dim: usize, args: Vec<Arg>) {
        self.steps.push(Step::Launch { abi, dim, args });
    }

    pub fn copy(
        &mut self,
        src: &str,
        src_offset: usize,
        dst: &str,
        dst_offset: usize,
        count: usize,
    ) {
        self.steps.push(Step::Copy {
            src: src.to_owned(),
            src_offset,
            dst: dst.to_owned(),
            dst_offset,
            count,
        });
    }

    pub fn buffer(&self, name: &str) -> &Buffer {
        self.buffers
            .iter()
            .find(|b| b.name == name)
            .unwrap_or_else(|| panic!("{}: no buffer {name}", self.name))
    }

    /// The initial values of a float32 buffer.
    pub fn input_f32(&self, name: &str) -> &[f32] {
        match &self.buffer(name).data {
            HostData::F32(v) => v,
            other => panic!("buffer {name} is {}", other.dtype_name()),
        }
    }

    pub fn input_f64(&self, name: &str) -> &[f64] {
        match &self.buffer(name).data {
            HostData::F64(v) => v,
            other => panic!("buffer {name} is {}", other.dtype_name()),
        }
    }

    pub fn input_i32(&self, name: &str) -> &[i32] {
        match &self.buffer(name).data {
            HostData::I32(v) => v,
            other => panic!("buffer {name} is {}", other.dtype_name()),
        }
    }

    /// Checks every launch against the kernel's ABI (as the launchers were generated): argument
    /// count, each buffer's element type and dimensionality, scalar types, struct names and
    /// fields (against the embedded manifest), the launch contract, and every copy's range. Both executions run this
    /// first, so that a case that does not fit the kernel fails with its name.
    pub fn validate(&self) -> Result<(), String> {
        let manifest = embedded_manifest();
        for (i, step) in self.steps.iter().enumerate() {
            let at = format!("{}, step {i}", self.name);
            match step {
                Step::Launch { abi, dim, args } => {
                    if args.len() != abi.params.len() {
                        return Err(format!(
                            "{at}: {} takes {} arguments, {} given",
                            abi.name,
                            abi.params.len(),
                            args.len()
                        ));
                    }
                    if *dim == 0 {
                        return Err(format!("{at}: a launch of 0 threads checks nothing"));
                    }
                    for (param, arg) in abi.params.iter().zip(args) {
                        self.check_arg(&manifest, &at, abi.name, param, arg)?;
                    }
                    // The kernel's launch contract, as the generated launcher checks it.
                    let shapes: Vec<Option<&[usize]>> = args
                        .iter()
                        .map(|arg| match arg {
                            Arg::Buffer(name) => {
                                self.find(name, &at).ok().map(|b| b.shape.as_slice())
                            }
                            _ => None,
                        })
                        .collect();
                    abi.check_launch(&[*dim], &shapes)
                        .map_err(|e| format!("{at}: {e}"))?;
                }
                Step::Copy {
                    src,
                    src_offset,
                    dst,
                    dst_offset,
                    count,
                } => {
                    let (s, d) = (self.find(src, &at)?, self.find(dst, &at)?);
                    if s.data.scalar() != d.data.scalar()
                        || src_offset + count > s.data.len()
                        || dst_offset + count > d.data.len()
                    {
                        return Err(format!(
                            "{at}: copy {src}[{src_offset}..+{count}] to {dst}[{dst_offset}..] does not fit"
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    fn find(&self, name: &str, at: &str) -> Result<&Buffer, String> {
        self.buffers
            .iter()
            .find(|b| b.name == name)
            .ok_or_else(|| format!("{at}: no buffer {name}"))
    }

    fn check_arg(
        &self,
        manifest: &EnvManifest,
        at: &str,
        kernel: &str,
        param: &instantmimic::kernels::ParamAbi,
        arg: &Arg,
    ) -> Result<(), String> {
        let at = format!("{at}: {kernel}({})", param.name);
        match (param.kind, arg) {
            (
                ParamKind::Array {
                    scalar,
                    shape,
                    ndim,
                },
                Arg::Buffer(name),
            ) => {
                let b = self.find(name, &at)?;
                if !shape.is_empty() || b.data.scalar() != scalar || b.shape.len() != ndim {
                    return Err(format!(
                        "{at}: buffer {name} is {:?} {:?}, the kernel takes a {ndim}-D array of {scalar:?}{shape:?}",
                        b.data.scalar(),
                        b.shape
                    ));
                }
            }
            (ParamKind::Value { scalar, shape }, Arg::Scalar(v)) => {
                if !shape.is_empty() || v.scalar() != scalar {
                    return Err(format!(
                        "{at}: {v:?} given, the kernel takes {scalar:?}{shape:?}"
                    ));
                }
            }
            (ParamKind::Struct { name }, Arg::Struct(s)) => {
                if s.name() != name {
                    return Err(format!("{at}: {} given, the kernel takes {name}", s.name()));
                }
                let def = manifest
                    .structs
                    .get(name)
                    .ok_or_else(|| format!("{at}: the manifest has no struct {name}"))?;
                let declared: Vec<(&str, Option<ScalarType>)> = def
                    .fields
                    .iter()
                    .map(|f| {
                        let scalar = match &f.ty {
                            SlotType::Value(d) if d.shape.is_empty() => Some(d.scalar),
                            _ => None,
                        };
                        (f.name.as_str(), scalar)
                    })
                    .collect();
                let given: Vec<(&str, Option<ScalarType>)> = s
                    .fields()
                    .iter()
                    .map(|(n, v)| (*n, Some(v.scalar())))
                    .collect();
                if declared != given {
                    return Err(format!(
                        "{at}: fields {given:?}, the manifest declares {declared:?}"
                    ));
                }
            }
            (kind, arg) => return Err(format!("{at}: {arg:?} given for a {kind:?} parameter")),
        }
        Ok(())
    }
}

/// `ptx/env/manifest.json` as embedded in the library.
pub fn embedded_manifest() -> EnvManifest {
    let bytes = instantmimic::assets::get(MANIFEST_ASSET).expect("the env manifest is embedded");
    let text = std::str::from_utf8(bytes).expect("the manifest is UTF-8");
    EnvManifest::parse(text).expect("the embedded manifest parses")
}
