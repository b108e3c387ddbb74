//! The env kernel pipeline on the CPU: the embedded manifest, the launchers build.rs generated
//! from it, the PTX it describes, Warp's ABI as the Rust side writes it, and the generator on
//! manifests with structs, vectors and 2-D launches.

// The generator as build.rs uses it, with the manifest module where it expects it.
mod manifest {
    pub use instantmimic::kernels::manifest::*;
}
#[path = "../build/env_codegen.rs"]
mod env_codegen;

use instantmimic::assets;
use instantmimic::kernels::abi::{ARRAY_DESCRIPTOR_BYTES, array_descriptor, launch_bounds};
use instantmimic::kernels::manifest::{
    ARRAY_LAYOUT, EnvManifest, ManifestError, SlotType, c_layout, launch_bounds_layout,
    ptx_entry_params,
};
use instantmimic::kernels::{ArgBuffer, KERNELS, LOOKUP_REFERENCE, MANIFEST_ASSET, ParamKind};
use instantmimic::motion::rotation::SLERP_LINEAR_BELOW;
use instantmimic::motion::table::{
    HEADER_CYCLE_DISPLACEMENT, HEADER_DURATION, HEADER_LEN, HEADER_NUM_ROWS, HEADER_ROW_DT,
    HEADER_ROW_STRIDE, HEADER_WRAP,
};
use serde_json::{Value, json};

/// The kernels this build must have, by module. Adding a kernel means adding it here.
const EXPECTED_KERNELS: [(&str, &str); 51] = [
    ("control", "pd_control"),
    ("control", "pd_targets"),
    ("evaluate", "evaluation_accumulate"),
    ("gae", "gae_advantages"),
    ("gae", "value_statistics_update"),
    ("gemm_epilogue", "bias_elu"),
    ("gemm_epilogue", "bias_add"),
    ("gemm_epilogue", "elu_input_gradient"),
    ("goal", "goal_reward_termination"),
    ("goal", "goal_reset"),
    ("goal", "goal_observe"),
    ("kinematics", "body_frames"),
    ("kinematics", "body_velocities"),
    ("latent", "latent_split_observation"),
    ("latent", "latent_sample"),
    ("latent", "latent_reconstruction_gradient"),
    ("latent", "latent_z_gradient"),
    ("latent", "latent_kl_gradients"),
    ("latent", "latent_gather"),
    ("latent", "latent_advance_counter"),
    ("latent", "latent_prior_residual"),
    ("minibatch", "shuffle_indices"),
    ("minibatch", "gather_minibatch"),
    ("mirror", "mirror_rows"),
    ("mirror", "mirror_log_probs"),
    ("mlp_backward", "linear_backward_weight"),
    ("mlp_backward", "linear_backward_input_elu"),
    ("observe", "observe"),
    ("observe", "observation_moments"),
    ("observe", "observation_moments_merge"),
    ("observe", "observation_normalize"),
    ("optimizer", "ppo_minibatch_schedule"),
    ("optimizer", "adam_advance"),
    ("optimizer", "adam_update"),
    ("optimizer", "log_std_floor"),
    ("optimizer", "parameter_average"),
    ("policy", "linear_elu"),
    ("policy", "linear"),
    ("policy", "gaussian_sample"),
    ("ppo_loss", "ppo_loss_gradients"),
    ("ppo_statistics", "ppo_update_statistics"),
    ("reduce", "column_sums"),
    ("reduce", "sum_of_squares"),
    ("reduce", "sum_and_squares"),
    ("reference", "lookup_reference"),
    ("reset", "reset_masked"),
    ("reset", "phase_statistics_update"),
    ("statistics", "episode_statistics"),
    ("statistics", "rollout_statistics"),
    ("tracking", "tracking_error_sums"),
    ("tracking", "reward_termination"),
];

fn manifest_text() -> &'static str {
    let bytes = assets::get(MANIFEST_ASSET).expect("ptx/env/manifest.json is embedded");
    std::str::from_utf8(bytes).expect("the manifest is UTF-8")
}

fn manifest() -> EnvManifest {
    EnvManifest::parse(manifest_text()).expect("the embedded manifest is valid")
}

fn ptx_text(path: &str) -> String {
    let bytes = assets::get(path).unwrap_or_else(|| panic!("{path} is embedded"));
    String::from_utf8_lossy(bytes).into_owned()
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
}

fn u64_at(bytes: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap())
}

#[test]
fn the_embedded_manifest_lists_the_expected_kernels() {
    let m = manifest();
    assert_eq!(m.warp_version, "1.19.0");
    assert_eq!(m.ptx_arch, 80);
    let kernels: Vec<(&str, &str)> = m
        .kernels()
        .map(|(module, k)| (module.name.as_str(), k.name.as_str()))
        .collect();
    assert_eq!(kernels, EXPECTED_KERNELS);
    for module in &m.modules {
        assert_eq!(module.ptx, format!("env/{}.ptx", module.name));
        assert_eq!(module.source, format!("kernels_py/env/{}.py", module.name));
        for k in &module.kernels {
            assert_eq!(k.entry, format!("{}_cuda_kernel_forward", k.name));
        }
    }
}

#[test]
fn the_generated_launchers_match_the_manifest() {
    let m = manifest();
    let described: Vec<_> = m.kernels().collect();
    assert_eq!(
        KERNELS.len(),
        described.len(),
        "build.rs generated a launcher per kernel"
    );
    for (abi, (module, k)) in KERNELS.iter().zip(described) {
        assert_eq!(abi.name, k.name);
        assert_eq!(abi.module, module.name);
        assert_eq!(abi.ptx, module.ptx);
        assert_eq!(abi.entry, k.entry);
        assert_eq!(abi.dim, k.dim);
        assert_eq!(abi.block_dim, k.block_dim);
        assert_eq!(abi.smem_bytes, k.smem_bytes);
        assert_eq!(abi.params.len(), k.params.len());
        for (p, slot) in abi.params.iter().zip(&k.params) {
            assert_eq!(
                (p.name, p.offset, p.size, p.align),
                (slot.name.as_str(), slot.offset, slot.size, slot.align)
            );
            match (&p.kind, &slot.ty) {
                (ParamKind::Value { scalar, shape }, SlotType::Value(d)) => {
                    assert_eq!((*scalar, *shape), (d.scalar, d.shape.as_slice()));
                }
                (
                    ParamKind::Array {
                        scalar,
                        shape,
                        ndim,
                    },
                    SlotType::Array { dtype, ndim: n },
                ) => {
                    assert_eq!(
                        (*scalar, *shape, *ndim),
                        (dtype.scalar, dtype.shape.as_slice(), *n)
                    );
                }
                (ParamKind::Struct { name }, SlotType::Struct(s)) => assert_eq!(name, s),
                (kind, ty) => panic!("{}.{}: generated {kind:?}, manifest {ty:?}", k.name, p.name),
            }
        }
        assert_eq!(abi.param_layout(), k.param_layout());
        assert_eq!(abi.param_bytes(), k.param_bytes());
        for (p, slot) in abi.params.iter().zip(&k.params) {
            assert_eq!(Some(p.io), slot.io, "{}.{}", k.name, p.name);
        }
        let rules = k.launch_rules().unwrap();
        assert_eq!(abi.launch.len(), rules.len());
        for (generated, rule) in abi.launch.iter().zip(&rules) {
            assert_eq!(*generated, rule.as_launch_rule(), "{}", k.name);
        }
    }
}

#[test]
fn every_kernel_has_a_launch_contract_covering_each_launch_axis() {
    for (_, k) in manifest().kernels() {
        let rules = k.launch_rules().unwrap();
        for axis in 0..k.dim {
            assert!(
                rules.iter().any(|r| r.axis == axis),
                "{}: no rule for axis {axis}",
                k.name
            );
        }
    }
}

#[test]
fn launch_contracts_and_directions_are_validated() {
    for (rules, expected) in [
        (json!([]), "no launch rule for axis 0"),
        (json!(["dim == extent(nothing, 0)"]), "no parameter nothing"),
        (
            json!(["dim == extent(dof_damping, 1)"]),
            "axis 1 of parameter dof_damping",
        ),
        (json!(["dim <= len(dof_damping) * "]), "found the end"),
        (json!(["dim[1] == len(table)"]), "axis 1 of a 1-D launch"),
        (json!(["threads == len(table)"]), "expected `dim`"),
        (json!(["dim != len(table)"]), "unexpected '!'"),
    ] {
        let err =
            parse_edited(|v| v["modules"][0]["kernels"][0]["launch"] = rules.clone()).unwrap_err();
        let err = err.to_string();
        assert!(err.contains(expected), "{rules}: {err}");
        assert!(err.contains("pd_control"), "{err}");
    }
    let err = parse_edited(|v| {
        let p = first_param(v, 0).as_object_mut().unwrap();
        p.remove("io");
    })
    .unwrap_err();
    assert!(err.to_string().contains("no `io`"), "{err}");
    let err = parse_edited(|v| first_param(v, 0)["io"] = json!("sideways")).unwrap_err();
    assert!(matches!(err, ManifestError::Json(_)), "{err}");
}

#[test]
fn a_launch_that_breaks_its_contract_names_the_kernel_the_dimension_and_the_arrays() {
    // lookup_reference: `dim == extent(out, 0)`, `dim <= len(clips)`, `dim <= len(times)`.
    let mut args = ArgBuffer::new(&LOOKUP_REFERENCE).unwrap();
    let clips = array_descriptor(&[16], 4).unwrap();
    let times = array_descriptor(&[16], 4).unwrap();
    let out = array_descriptor(&[16, 282], 4).unwrap();
    args.set_array_descriptor::<i32>(4, 1, &clips).unwrap();
    args.set_array_descriptor::<f32>(5, 1, &times).unwrap();
    let err = args.check_launch(&[16]).unwrap_err().to_string();
    assert!(err.contains("out (not given)"), "{err}");
    args.set_array_descriptor::<f32>(6, 2, &out).unwrap();
    args.check_launch(&[16]).unwrap();
    let err = args.check_launch(&[17]).unwrap_err().to_string();
    for expected in [
        "kernel lookup_reference",
        "[17]",
        "`dim == extent(out, 0)`",
        "out [16, 282]",
        "is 17, the contract's bound is 16",
        "LAUNCH at the end of kernels_py/env/reference.py",
    ] {
        assert!(err.contains(expected), "missing {expected:?} in {err}");
    }
    let short = array_descriptor(&[8], 4).unwrap();
    args.set_array_descriptor::<f32>(5, 1, &short).unwrap();
    let err = args.check_launch(&[16]).unwrap_err().to_string();
    assert!(err.contains("`dim <= len(times)`"), "{err}");
    assert!(err.contains("times [8]"), "{err}");
    args.set_array_descriptor::<f32>(5, 1, &times).unwrap();
    args.set_array_descriptor::<i32>(4, 1, &short).unwrap();
    let err = args.check_launch(&[16]).unwrap_err().to_string();
    assert!(err.contains("`dim <= len(clips)`"), "{err}");
}

#[test]
fn parameter_offsets_follow_c_layout_and_the_ptx_declarations() {
    let m = manifest();
    for (module, k) in m.kernels() {
        // Offsets recomputed here from sizes and alignments alone.
        let bounds = launch_bounds_layout(k.dim);
        let fields: Vec<(usize, usize)> = k.params.iter().map(|p| (p.size, p.align)).collect();
        let (offsets, end) = c_layout(bounds.size, &fields);
        let recorded: Vec<usize> = k.params.iter().map(|p| p.offset).collect();
        assert_eq!(offsets, recorded, "{}: offsets", k.name);
        assert_eq!(end, k.param_bytes());

        // What NVRTC declared in the PTX this binary embeds.
        let ptx = ptx_text(&module.ptx);
        let declared = ptx_entry_params(&ptx, &k.entry).expect("the entry is in the PTX");
        let mut described = vec![(bounds.size, bounds.align)];
        described.extend(fields);
        assert_eq!(declared, described, "{}: PTX .param declarations", k.name);
        k.check_ptx(&ptx).expect("check_ptx agrees");
    }
    // The reference lookup: launch_bounds_t<1> (24 bytes), then seven array_t (56 bytes each).
    assert_eq!(
        LOOKUP_REFERENCE.param_layout(),
        [
            (0, 24),
            (24, 56),
            (80, 56),
            (136, 56),
            (192, 56),
            (248, 56),
            (304, 56),
            (360, 56)
        ]
    );
}

#[test]
fn the_array_descriptor_is_warps_array_t() {
    let f = ARRAY_LAYOUT.fields;
    let d = array_descriptor(&[3, 282], 4).unwrap();
    assert_eq!(d.len(), ARRAY_DESCRIPTOR_BYTES);
    // The data pointer is written by ArgBuffer::set_array from the array's DeviceRange.
    assert_eq!(u64_at(&d, f.data), 0);
    assert_eq!(u64_at(&d, f.grad), 0);
    let shape: Vec<u32> = (0..4).map(|i| u32_at(&d, f.shape + 4 * i)).collect();
    let strides: Vec<u32> = (0..4).map(|i| u32_at(&d, f.strides + 4 * i)).collect();
    assert_eq!(shape, [3, 282, 0, 0]);
    assert_eq!(strides, [282 * 4, 4, 0, 0], "byte strides, row-major");
    assert_eq!(u16::from_le_bytes([d[f.ndim], d[f.ndim + 1]]), 2);
    assert_eq!(u16::from_le_bytes([d[f.flags], d[f.flags + 1]]), 0);
    assert!(d[52..].iter().all(|&b| b == 0), "padding is zero");

    let vec3 = array_descriptor(&[10, 15], 12).unwrap();
    assert_eq!(u32_at(&vec3, f.strides), 15 * 12);
    assert_eq!(u32_at(&vec3, f.strides + 4), 12);

    assert!(array_descriptor(&[], 4).is_err());
    assert!(array_descriptor(&[1, 1, 1, 1, 1], 4).is_err());
    assert!(
        array_descriptor(&[1 << 31], 4).is_err(),
        "extent beyond int"
    );
    assert!(
        array_descriptor(&[2, 1 << 30], 4).is_err(),
        "row stride beyond int"
    );
    assert!(
        array_descriptor(&[1 << 20, 1 << 10], 4).is_ok(),
        "4 GiB in rows that fit"
    );
}

#[test]
fn launch_bounds_are_warps_launch_bounds_t() {
    let (b, size) = launch_bounds(&[4096]).unwrap();
    assert_eq!((b.len(), size), (24, 4096));
    assert_eq!(u32_at(&b, 0), 4096);
    assert_eq!(u32_at(&b, 4), 0, "padding");
    assert_eq!(u64_at(&b, 8), 4096, "size");
    assert_eq!(u64_at(&b, 16), 1, "coord_mult");

    let (b, size) = launch_bounds(&[7, 5, 3]).unwrap();
    assert_eq!((b.len(), size), (32, 105));
    assert_eq!([u32_at(&b, 0), u32_at(&b, 4), u32_at(&b, 8)], [7, 5, 3]);
    assert_eq!((u64_at(&b, 16), u64_at(&b, 24)), (105, 1));

    for dim in 1..=4 {
        let layout = launch_bounds_layout(dim);
        assert_eq!(launch_bounds(&vec![2; dim]).unwrap().0.len(), layout.size);
    }
    assert!(launch_bounds(&[]).is_err());
    assert!(launch_bounds(&[1; 5]).is_err());
    assert!(launch_bounds(&[1 << 31]).is_err());
}

#[test]
fn the_argument_buffer_puts_each_parameter_at_its_offset_and_checks_its_type() {
    let mut args = ArgBuffer::new(&LOOKUP_REFERENCE).unwrap();
    assert_eq!(args.bytes().len(), 416);
    let table = array_descriptor(&[8 + 2 * 282], 4).unwrap();
    let out = array_descriptor(&[16, 282], 4).unwrap();
    args.set_array_descriptor::<f32>(0, 1, &table).unwrap();
    args.set_array_descriptor::<f32>(6, 2, &out).unwrap();
    assert_eq!(args.set_launch_bounds(&[16]).unwrap(), 16);
    let bytes = args.bytes();
    assert_eq!(&bytes[24..80], &table);
    assert_eq!(&bytes[360..416], &out);
    assert!(
        bytes[80..360].iter().all(|&b| b == 0),
        "unset parameters stay zero"
    );
    assert_eq!(u32_at(bytes, 0), 16);

    // Wrong element type, wrong ndim, a value for an array, a parameter that does not exist,
    // a 2-D launch of a 1-D kernel.
    assert!(args.set_array_descriptor::<f32>(1, 1, &table).is_err());
    assert!(args.set_array_descriptor::<f32>(6, 1, &table).is_err());
    assert!(args.set_array_descriptor::<[f32; 3]>(0, 1, &table).is_err());
    assert!(args.set_value(0, &1.0f32).is_err());
    assert!(args.set_array_descriptor::<f32>(7, 1, &table).is_err());
    let err = args.set_launch_bounds(&[4, 4]).unwrap_err();
    assert!(err.to_string().contains("1 dimension"), "{err}");
}

/// The manifest as JSON, changed by `edit`, parsed.
fn parse_edited(edit: impl FnOnce(&mut Value)) -> Result<EnvManifest, ManifestError> {
    let mut v: Value = serde_json::from_str(manifest_text()).unwrap();
    edit(&mut v);
    EnvManifest::parse(&v.to_string())
}

fn first_param(v: &mut Value, index: usize) -> &mut Value {
    &mut v["modules"][0]["kernels"][0]["params"][index]
}

#[test]
fn manifest_validation_says_what_is_wrong() {
    let err = parse_edited(|v| v["format"] = json!(1)).unwrap_err();
    assert!(
        matches!(err, ManifestError::Format { found: 1, .. }),
        "{err}"
    );

    let err = parse_edited(|v| v["abi"]["array"]["fields"]["ndim"] = json!(52)).unwrap_err();
    assert!(matches!(err, ManifestError::WarpAbi { .. }), "{err}");
    assert!(err.to_string().contains("array_t"), "{err}");

    let err = parse_edited(|v| v["abi"]["launch_bounds"][2]["size"] = json!(24)).unwrap_err();
    assert!(err.to_string().contains("launch_bounds_t"), "{err}");

    let err = parse_edited(|v| first_param(v, 2)["offset"] = json!(140)).unwrap_err();
    assert!(err.to_string().contains("C layout puts it at 136"), "{err}");

    let err = parse_edited(|v| first_param(v, 0)["size"] = json!(48)).unwrap_err();
    assert!(err.to_string().contains("size 48"), "{err}");

    let err = parse_edited(|v| first_param(v, 3)["name"] = json!("stream")).unwrap_err();
    assert!(err.to_string().contains("rename the parameter"), "{err}");

    let err = parse_edited(|v| first_param(v, 3)["name"] = json!("times-1")).unwrap_err();
    assert!(err.to_string().contains("Rust identifier"), "{err}");

    let err = parse_edited(|v| first_param(v, 0)["kind"] = json!("pointer")).unwrap_err();
    assert!(err.to_string().contains("\"pointer\""), "{err}");

    let err = parse_edited(|v| v["modules"][0]["kernels"][0]["dim"] = json!(5)).unwrap_err();
    assert!(err.to_string().contains("launch dimension 5"), "{err}");

    let err = parse_edited(|v| {
        let kernel = v["modules"][0]["kernels"][0].clone();
        v["modules"][0]["kernels"]
            .as_array_mut()
            .unwrap()
            .push(kernel);
    })
    .unwrap_err();
    assert!(err.to_string().contains("two kernels"), "{err}");

    let err = parse_edited(|v| {
        first_param(v, 0)["kind"] = json!("struct");
        first_param(v, 0)["struct"] = json!("Missing");
        let p = first_param(v, 0).as_object_mut().unwrap();
        p.remove("dtype");
        p.remove("ndim");
    })
    .unwrap_err();
    assert!(err.to_string().contains("struct Missing"), "{err}");

    assert!(matches!(
        EnvManifest::parse("{\"format\": 1"),
        Err(ManifestError::Json(_))
    ));
}

#[test]
fn a_kernel_whose_ptx_declares_other_parameters_is_refused() {
    let m = manifest();
    let (_, k) = m
        .kernels()
        .find(|(_, k)| k.name == "lookup_reference")
        .expect("lookup_reference in the manifest");
    let ptx = ptx_text(LOOKUP_REFERENCE.ptx);
    // One parameter fewer than the manifest describes.
    let cut = ptx.replacen(
        &format!(",\n\t.param .align 8 .b8 {}_param_5[56]", k.entry),
        "",
        1,
    );
    assert_ne!(cut, ptx, "the PTX has the parameter this test removes");
    let err = k.check_ptx(&cut).unwrap_err();
    assert!(matches!(err, ManifestError::PtxMismatch { .. }), "{err}");
    assert!(err.to_string().contains("regenerate"), "{err}");

    let renamed = ptx.replace(&k.entry, "other_entry");
    assert!(
        k.check_ptx(&renamed)
            .unwrap_err()
            .to_string()
            .contains("no `.entry")
    );

    assert_eq!(
        ptx_entry_params(
            ".visible .entry k(\n\t.param .align 8 .b8 k_param_0[24],\n\t.param .f32 k_param_1,\n\t.param .u8 k_param_2,\n\t.param .align 4 .b8 k_param_3[12]\n)",
            "k"
        )
        .unwrap(),
        [(24, 8), (4, 4), (1, 1), (12, 4)]
    );
}

/// `NAME = wp.constant(VALUE)` lines of a Python file.
fn python_constants(source: &str) -> Vec<(String, f64)> {
    source
        .lines()
        .filter_map(|line| {
            let (name, rest) = line.split_once(" = wp.constant(")?;
            let value = rest.strip_suffix(')')?.parse::<f64>().ok()?;
            Some((name.trim().to_owned(), value))
        })
        .collect()
}

#[test]
fn the_python_lookup_uses_the_tables_constants() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/kernels_py/env/reference.py");
    let source = std::fs::read_to_string(path).expect("kernels_py/env/reference.py");
    let constants = python_constants(&source);
    let expected = [
        ("HEADER_LEN", HEADER_LEN as f64),
        ("HEADER_NUM_ROWS", HEADER_NUM_ROWS as f64),
        ("HEADER_ROW_DT", HEADER_ROW_DT as f64),
        ("HEADER_DURATION", HEADER_DURATION as f64),
        ("HEADER_WRAP", HEADER_WRAP as f64),
        (
            "HEADER_CYCLE_DISPLACEMENT",
            HEADER_CYCLE_DISPLACEMENT as f64,
        ),
        ("HEADER_ROW_STRIDE", HEADER_ROW_STRIDE as f64),
        ("SLERP_LINEAR_BELOW", SLERP_LINEAR_BELOW),
    ];
    for (name, value) in expected {
        let found = constants.iter().find(|(n, _)| n == name);
        assert_eq!(
            found.map(|(_, v)| *v),
            Some(value),
            "{name} in kernels_py/env/reference.py"
        );
    }
}

/// A manifest with a struct parameter, vector and matrix values and a 2-D launch, as
/// env_build.py would write it (offsets by C rules).
fn synthetic_manifest(struct_fields: Value) -> Value {
    let abi: Value = serde_json::from_str::<Value>(manifest_text()).unwrap()["abi"].clone();
    json!({
        "format": 2,
        "warp_version": "1.19.0",
        "ptx_arch": 80,
        "abi": abi,
        "structs": {"RewardWeights": {"fields": struct_fields, "size": 20, "align": 4}},
        "modules": [{
            "name": "reward",
            "source": "kernels_py/env/reward.py",
            "ptx": "env/reward.ptx",
            "kernels": [{
                "name": "compute_reward",
                "entry": "compute_reward_cuda_kernel_forward",
                "dim": 2,
                "block_dim": 128,
                "smem_bytes": 0,
                "doc": "Rewards.\n\nOne per env and term.",
                "launch": ["dim[0] == extent(pos, 0)", "dim[1] <= cdiv(extent(pos, 1) + 1, 2)"],
                "params": [
                    {"name": "pos", "kind": "array", "dtype": {"warp": "vec3f", "scalar": "float32", "shape": [3]}, "ndim": 2, "size": 56, "align": 8, "offset": 24, "io": "in"},
                    {"name": "weights", "kind": "struct", "struct": "RewardWeights", "size": 20, "align": 4, "offset": 80, "io": "in"},
                    {"name": "scale", "kind": "scalar", "dtype": {"warp": "float64", "scalar": "float64", "shape": []}, "size": 8, "align": 8, "offset": 104, "io": "in"},
                    {"name": "rotation", "kind": "vector", "dtype": {"warp": "mat33f", "scalar": "float32", "shape": [3, 3]}, "size": 36, "align": 4, "offset": 112, "io": "in"},
                    {"name": "type", "kind": "scalar", "dtype": {"warp": "bool", "scalar": "bool", "shape": []}, "size": 1, "align": 1, "offset": 148, "io": "in"}
                ]
            }]
        }]
    })
}

fn value_fields() -> Value {
    json!([
        {"name": "pose", "kind": "scalar", "dtype": {"warp": "float32", "scalar": "float32", "shape": []}, "size": 4, "align": 4, "offset": 0},
        {"name": "target", "kind": "vector", "dtype": {"warp": "vec3f", "scalar": "float32", "shape": [3]}, "size": 12, "align": 4, "offset": 4},
        {"name": "steps", "kind": "scalar", "dtype": {"warp": "int32", "scalar": "int32", "shape": []}, "size": 4, "align": 4, "offset": 16}
    ])
}

#[test]
fn the_generator_handles_structs_values_and_two_dimensional_launches() {
    let m = EnvManifest::parse(&synthetic_manifest(value_fields()).to_string()).unwrap();
    assert_eq!(
        m.kernels().next().unwrap().1.param_layout(),
        [(0, 24), (24, 56), (80, 20), (104, 8), (112, 36), (148, 1)]
    );
    let src = env_codegen::generate(&m).unwrap();
    for expected in [
        "pub struct RewardWeights {",
        "    pub pose: f32,",
        "    pub target: [f32; 3],",
        "    pub steps: i32,",
        "        write_field(out, 4, &self.target);",
        "        write_field(out, 16, &self.steps);",
        "    const SIZE: usize = 20;",
        "    pub fn compute_reward(",
        "        dim: [usize; 2],",
        "        pos_in: &DeviceArray<[f32; 3], 2>,",
        "        weights: &RewardWeights,",
        "        scale: f64,",
        "        rotation: [[f32; 3]; 3],",
        "        r#type: bool,",
        "        args.set_array(0, pos_in)?;",
        "        args.set_struct(1, weights)?;",
        "        args.set_value(2, &scale)?;",
        "        args.set_value(4, &r#type)?;",
        "        launch(stream, &self.compute_reward, args, &dim)",
        "    /// Rewards.\n    ///\n    /// One per env and term.",
        "kind: ParamKind::Value { scalar: ScalarType::Float32, shape: &[3, 3] }, offset: 112, size: 36, align: 4",
        "compute_reward: bind_kernel(&module_0, &COMPUTE_REWARD)?,",
        "io: Io::In },",
        "LaunchRule { axis: 0, relation: Relation::Equal, bound: &[Op::Extent { param: 0, axis: 0 }], text: \"dim[0] == extent(pos, 0)\" },",
        "LaunchRule { axis: 1, relation: Relation::AtMost, bound: &[Op::Extent { param: 0, axis: 1 }, Op::Const(1), Op::Add, Op::Const(2), Op::CeilDiv], text: \"dim[1] <= cdiv(extent(pos, 1) + 1, 2)\" },",
        "let module_0 = load_module(gpu, \"env/reward.ptx\")?;",
    ] {
        assert!(src.contains(expected), "missing {expected:?} in:\n{src}");
    }

    // Struct fields that are arrays are described but not generated yet: a clear build error.
    let mut fields = value_fields();
    fields[1] = json!({"name": "target", "kind": "array", "dtype": {"warp": "float32", "scalar": "float32", "shape": []}, "ndim": 1, "size": 56, "align": 8, "offset": 8});
    fields[2]["offset"] = json!(64);
    let mut v = synthetic_manifest(fields);
    v["structs"]["RewardWeights"]["size"] = json!(72);
    v["structs"]["RewardWeights"]["align"] = json!(8);
    let params = v["modules"][0]["kernels"][0]["params"]
        .as_array_mut()
        .unwrap();
    params[1]["size"] = json!(72);
    params[1]["align"] = json!(8);
    for (p, offset) in params.iter_mut().zip([24, 80, 152, 160, 196]) {
        p["offset"] = json!(offset);
    }
    let m = EnvManifest::parse(&v.to_string()).unwrap();
    let err = env_codegen::generate(&m).unwrap_err().to_string();
    assert!(err.contains("array fields in struct parameters"), "{err}");

    // A struct whose size does not follow from its fields.
    let mut v = synthetic_manifest(value_fields());
    v["structs"]["RewardWeights"]["size"] = json!(24);
    let err = EnvManifest::parse(&v.to_string()).unwrap_err().to_string();
    assert!(err.contains("struct RewardWeights"), "{err}");
}

#[test]
fn element_values_are_written_as_their_little_endian_bytes() {
    use instantmimic::kernels::abi::write_field;
    use instantmimic::kernels::{Element, ScalarType};

    fn written<T: Element>(value: &T) -> Vec<u8> {
        let mut out = vec![0xAAu8; T::SIZE + 2];
        write_field(&mut out, 1, value);
        assert_eq!(
            (out[0], out[T::SIZE + 1]),
            (0xAA, 0xAA),
            "only its own bytes"
        );
        out[1..=T::SIZE].to_vec()
    }
    assert_eq!(written(&-2i32), (-2i32).to_le_bytes());
    assert_eq!(written(&1.5f64), 1.5f64.to_le_bytes());
    assert_eq!(written(&true), [1]);
    assert_eq!(written(&half::f16::from_f32(1.0)), 0x3c00u16.to_le_bytes());
    let v = [1.0f32, -2.0, 3.5];
    let expected: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    assert_eq!(written(&v), expected);
    let m = [[1u16, 2, 3], [4, 5, 6]];
    let expected: Vec<u8> = m.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
    assert_eq!(written(&m), expected, "row-major");
    assert_eq!(
        (
            <[[u16; 3]; 2]>::SCALAR,
            <[[u16; 3]; 2]>::SHAPE,
            <[[u16; 3]; 2]>::SIZE
        ),
        (ScalarType::Uint16, &[2usize, 3][..], 12)
    );
    assert_eq!((<[f32; 3]>::SHAPE, <[f32; 3]>::SIZE), (&[3usize][..], 12));
    assert_eq!((bool::SCALAR, bool::SIZE), (ScalarType::Bool, 1));
}
