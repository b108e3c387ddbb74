//! The `.wrp` plan reader, writer and packer, on a real Warp-written plan and on synthetic
//! plans built here (CPU only, no data files needed).

mod plan_support;

use std::collections::BTreeMap;

use instantmimic::plan::{
    self, DeviceType, Op, OpKind, Plan, PlanError, PlanInfo, PlanSummary, RelocationTarget,
    WhileOp, load_plan, load_plan_with_limit, pack,
};
use plan_support::{
    Rng, every_kind_plan, put_u32, put_u64, read_u32, section_offset, synthetic_plan,
    top_level_op_offsets,
};

/// One `mujoco_warp.step` of a 2-link pendulum and a free box, 2 worlds, captured on the Warp
/// CPU device by `kernels_py/fixtures/make_test_plan.py`.
const FIXTURE: &[u8] = include_bytes!("fixtures/pendulum_cpu.wrp");

fn parse_fixture() -> Plan {
    match Plan::parse(FIXTURE) {
        Ok(plan) => plan,
        Err(err) => panic!("the fixture does not parse: {err}"),
    }
}

fn parse_err(bytes: &[u8]) -> PlanError {
    match Plan::parse(bytes) {
        Ok(_) => panic!("a corrupt plan parsed"),
        Err(err) => err,
    }
}

fn counts(pairs: &[(&str, usize)]) -> BTreeMap<String, usize> {
    pairs.iter().map(|&(k, v)| (k.to_string(), v)).collect()
}

#[test]
fn fixture_counts_match_wrp_inspect() {
    // `python /work/shared/tools/wrp_inspect.py tests/fixtures/pendulum_cpu.wrp` prints:
    //   magic b'WRP1' version 18 device cpu arch 0
    //   producer warp 1.19.0: 36 modules, 64 kernels, 3 bindings, 0 meshes
    //   kernel block dims: {1: 64}
    //   binding d.qpos -> region 14 / d.qvel -> region 101 / d.ctrl -> region 174
    //   regions 231: 19773 bytes, 19773 with initial contents
    //   ops 73 at top level: launch 57, memcpy_d2d 2, memset 12, memtile 1, while 1;
    //   nested: launch 10
    let plan = parse_fixture();
    assert_eq!(plan.header.version, 18);
    assert_eq!(plan.header.device, DeviceType::Cpu);
    assert_eq!(plan.header.target_arch, 0);
    assert_eq!(plan.producer, "1.19.0");
    assert_eq!(plan.meshes.len(), 0);
    assert!(plan.info().is_none());

    let summary = PlanSummary::of(&plan);
    assert_eq!(summary.modules, 36);
    assert_eq!(summary.kernels, 64);
    assert_eq!(summary.kernel_block_dims, BTreeMap::from([(1, 64)]));
    assert_eq!(summary.regions, 231);
    assert_eq!(summary.region_bytes, 19773);
    assert_eq!(summary.initial_data_bytes, 19773);
    assert_eq!(summary.top_level_ops, 73);
    assert_eq!(
        summary.op_counts_by_depth,
        vec![
            counts(&[
                ("launch", 57),
                ("memcpy_d2d", 2),
                ("memset", 12),
                ("memtile", 1),
                ("while", 1)
            ]),
            counts(&[("launch", 10)]),
        ]
    );
    let bindings: Vec<(&str, u32)> = summary
        .bindings
        .iter()
        .map(|b| (b.name.as_str(), b.region))
        .collect();
    assert_eq!(
        bindings,
        vec![("d.ctrl", 174), ("d.qpos", 14), ("d.qvel", 101)]
    );
    // 2 worlds x 9 qpos (2 hinges + free joint) as float32.
    assert_eq!(plan.binding("d.qpos").map(|r| r.size), Some(72));
}

#[test]
fn fixture_launches_name_kernels_and_modules_of_the_metadata() {
    let plan = parse_fixture();
    let mut launches = 0;
    plan::walk_ops(&plan.ops, &mut |op, _| {
        if let Op::KernelLaunch(launch) = op {
            launches += 1;
            assert!(
                plan.kernel(&launch.module_hash, &launch.kernel_key)
                    .is_some()
            );
            assert!(plan.module(&launch.module_hash).is_some());
            assert!(launch.is_forward && launch.adjoint_params.is_empty());
            for param in &launch.params {
                assert!(launch.value(param).is_some());
            }
        }
    });
    assert_eq!(launches, 67);
}

#[test]
fn fixture_round_trips_byte_for_byte() {
    let plan = parse_fixture();
    let bytes = plan.to_bytes();
    assert_eq!(bytes.len(), FIXTURE.len());
    assert!(
        bytes == FIXTURE,
        "the written plan differs from the file Warp wrote"
    );
}

#[test]
fn packing_keeps_everything_but_all_zero_initial_data() {
    let raw = parse_fixture();
    let info = plan_support::step_info();
    let packed = match pack(FIXTURE, &info) {
        Ok(packed) => packed,
        Err(err) => panic!("pack failed: {err}"),
    };
    assert!(
        packed.len() * 4 < FIXTURE.len(),
        "packed {} bytes",
        packed.len()
    );
    let loaded = match load_plan(&packed) {
        Ok(plan) => plan,
        Err(err) => panic!("the packed plan does not load: {err}"),
    };
    assert_eq!(loaded.info(), Some(&info));

    let mut dropped = 0;
    for (before, after) in raw.regions.iter().zip(&loaded.regions) {
        assert_eq!(
            (before.id, before.size, before.element_size),
            (after.id, after.size, after.element_size)
        );
        if before.initial_data != after.initial_data {
            assert!(after.initial_data.is_none());
            assert!(before.initial_data.iter().flatten().all(|&b| b == 0));
            dropped += 1;
        }
    }
    assert!(dropped > 0, "the fixture has all-zero regions to drop");
    let mut expected = raw.clone();
    expected.drop_zero_initial_data();
    expected.info = Some(info);
    assert_eq!(loaded, expected);
    // A raw file still loads through the same entry point.
    assert_eq!(load_plan(FIXTURE).ok(), Some(raw));
}

#[test]
fn synthetic_plans_round_trip() {
    for plan in [synthetic_plan(), every_kind_plan()] {
        let bytes = plan.to_bytes();
        let parsed = Plan::parse(&bytes).map_err(|e| e.to_string());
        assert_eq!(parsed.as_ref(), Ok(&plan));
        assert_eq!(parsed.map(|p| p.to_bytes()), Ok(bytes));
    }
    let mut with_info = synthetic_plan();
    with_info.info = Some(PlanInfo {
        name: "kinematics".into(),
        nworld: 32,
        physics: serde_json::Map::new(),
    });
    let parsed = Plan::parse(&with_info.to_bytes()).map_err(|e| e.to_string());
    assert_eq!(parsed, Ok(with_info));
}

#[test]
fn every_kind_plan_covers_every_op_kind() {
    let mut seen = std::collections::BTreeSet::new();
    plan::walk_ops(&every_kind_plan().ops, &mut |op, _| {
        seen.insert(op.kind());
    });
    assert_eq!(seen.len(), OpKind::ALL.len());
}

#[test]
fn every_truncation_is_an_error() {
    for bytes in [synthetic_plan().to_bytes(), every_kind_plan().to_bytes()] {
        for len in 0..bytes.len() {
            match Plan::parse(&bytes[..len]) {
                Err(PlanError::Truncated { .. }) => {}
                other => {
                    panic!("prefix of {len} bytes: expected a truncation error, got {other:?}")
                }
            }
        }
    }
    // The fixture too, at a stride (every prefix would take too long in a debug build).
    for len in (0..FIXTURE.len()).step_by(997) {
        assert!(matches!(
            Plan::parse(&FIXTURE[..len]),
            Err(PlanError::Truncated { .. })
        ));
    }
}

#[test]
fn bad_magic_and_wrong_version_are_refused() {
    let mut bytes = synthetic_plan().to_bytes();
    bytes[0] = b'X';
    assert!(matches!(parse_err(&bytes), PlanError::BadMagic { .. }));
    assert!(matches!(
        load_plan(b"{\"json\": 1}"),
        Err(PlanError::BadMagic { .. })
    ));

    let mut bytes = synthetic_plan().to_bytes();
    put_u32(&mut bytes, 4, 17);
    let err = parse_err(&bytes);
    assert!(
        matches!(err, PlanError::UnsupportedVersion { found: 17, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("recapture"));

    // The metadata section repeats the version.
    let mut bytes = synthetic_plan().to_bytes();
    let metadata = section_offset(&bytes, 0);
    put_u32(&mut bytes, metadata, 19);
    assert!(matches!(
        parse_err(&bytes),
        PlanError::UnsupportedVersion { found: 19, .. }
    ));
}

#[test]
fn section_table_outside_the_file_is_truncation() {
    let mut bytes = synthetic_plan().to_bytes();
    let len = bytes.len() as u64;
    put_u64(&mut bytes, 16, len - 16);
    let err = parse_err(&bytes);
    assert!(matches!(err, PlanError::Truncated { .. }), "{err}");
    assert!(
        err.to_string()
            .starts_with("truncated: the section table needs 96 bytes"),
        "{err}"
    );

    let mut bytes = synthetic_plan().to_bytes();
    put_u64(&mut bytes, 16, u64::MAX - 8);
    assert!(matches!(parse_err(&bytes), PlanError::Truncated { .. }));

    // A section that points past the end of the file.
    let mut bytes = synthetic_plan().to_bytes();
    put_u64(&mut bytes, 64 + 32 + 8, u64::MAX);
    assert!(matches!(parse_err(&bytes), PlanError::Truncated { .. }));

    // Two sections over the same bytes.
    let mut bytes = synthetic_plan().to_bytes();
    let metadata = section_offset(&bytes, 0) as u64;
    put_u64(&mut bytes, 64 + 32 + 8, metadata);
    assert!(matches!(parse_err(&bytes), PlanError::Malformed { .. }));
}

#[test]
fn missing_regions_are_named_with_the_operation_and_byte() {
    let mut plan = synthetic_plan();
    if let Some(Op::Memset(memset)) = plan.ops.get_mut(1) {
        memset.dst.region = 999;
    }
    let bytes = plan.to_bytes();
    let memset_at = top_level_op_offsets(&bytes)[1];
    assert_eq!(
        parse_err(&bytes).to_string(),
        format!(
            "operation 1 (memset) at byte {memset_at}: region 999 does not exist (the plan has 3 regions)"
        )
    );
}

fn assert_missing_region(plan: &Plan, what: &str) {
    match Plan::parse(&plan.to_bytes()) {
        Err(PlanError::MissingRegion {
            region: 999,
            count: 3,
            ..
        }) => {}
        other => panic!("{what}: expected region 999 to be missing, got {other:?}"),
    }
}

#[test]
fn every_region_reference_is_checked() {
    let mut plan = synthetic_plan();
    if let Some(Op::KernelLaunch(launch)) = plan.ops.get_mut(0) {
        launch.params[0].relocations[0].target = RelocationTarget::DataPtr {
            region: 999,
            offset: 0,
        };
    }
    assert_missing_region(&plan, "relocation");

    let mut plan = synthetic_plan();
    plan.bindings[0].region = 999;
    assert_missing_region(&plan, "binding");

    let mut plan = synthetic_plan();
    if let Some(Op::While(op)) = plan.ops.get_mut(5) {
        op.cond.region = 999;
    }
    assert_missing_region(&plan, "while condition");

    let mut plan = synthetic_plan();
    if let Some(Op::MemcpyD2D(op)) = plan.ops.get_mut(3) {
        op.src.region = 999;
    }
    assert_missing_region(&plan, "d2d source");

    let mut plan = synthetic_plan();
    if let Some(Op::MemcpyH2D(op)) = plan.ops.get_mut(4) {
        op.dst.region = 999;
    }
    assert_missing_region(&plan, "h2d destination");

    // A launch nested in the WHILE body.
    let mut plan = synthetic_plan();
    if let Some(Op::While(op)) = plan.ops.get_mut(5)
        && let Some(Op::KernelLaunch(launch)) = op.body.get_mut(0)
    {
        launch.params[0].relocations[0].target = RelocationTarget::DataPtr {
            region: 999,
            offset: 0,
        };
    }
    let err = parse_err(&plan.to_bytes()).to_string();
    assert!(err.contains("operation 5 (while) at byte"), "{err}");
    assert!(err.contains(", body operation 0 (launch) at byte"), "{err}");
}

#[test]
fn spans_outside_regions_and_overflows_are_refused() {
    let mut plan = synthetic_plan();
    if let Some(Op::Memset(memset)) = plan.ops.get_mut(1) {
        memset.dst.offset = u64::MAX - 4;
    }
    assert!(matches!(
        parse_err(&plan.to_bytes()),
        PlanError::Overflow { .. }
    ));

    let mut plan = synthetic_plan();
    if let Some(Op::Memset(memset)) = plan.ops.get_mut(1) {
        memset.size = 17;
    }
    assert!(matches!(
        parse_err(&plan.to_bytes()),
        PlanError::OutOfBounds {
            len: 17,
            limit: 16,
            ..
        }
    ));

    let mut plan = synthetic_plan();
    if let Some(Op::Memtile(memtile)) = plan.ops.get_mut(2) {
        memtile.count = u64::MAX / 2;
    }
    assert!(matches!(
        parse_err(&plan.to_bytes()),
        PlanError::Overflow { .. }
    ));

    let mut plan = synthetic_plan();
    if let Some(Op::MemcpyD2D(op)) = plan.ops.get_mut(3) {
        op.src.offset = 56;
    }
    assert!(matches!(
        parse_err(&plan.to_bytes()),
        PlanError::OutOfBounds { .. }
    ));

    // A data pointer past the end of its region.
    let mut plan = synthetic_plan();
    if let Some(Op::KernelLaunch(launch)) = plan.ops.get_mut(0) {
        launch.params[0].relocations[0].target = RelocationTarget::DataPtr {
            region: 1,
            offset: 65,
        };
    }
    assert!(matches!(
        parse_err(&plan.to_bytes()),
        PlanError::OutOfBounds { .. }
    ));
}

#[test]
fn launch_value_slices_and_relocations_stay_inside_their_blobs() {
    let mut plan = synthetic_plan();
    if let Some(Op::KernelLaunch(launch)) = plan.ops.get_mut(0) {
        launch.params[1].value_offset = 58; // 4 bytes at 58 of 60
    }
    let err = parse_err(&plan.to_bytes());
    assert!(
        matches!(&err, PlanError::OutOfBounds { container, limit: 60, .. } if container == "value_data"),
        "{err}"
    );

    let mut plan = synthetic_plan();
    if let Some(Op::KernelLaunch(launch)) = plan.ops.get_mut(0) {
        launch.params[0].relocations[1].value_byte_offset = 52; // 8 bytes at 52 of a 56-byte blob
    }
    assert!(matches!(
        parse_err(&plan.to_bytes()),
        PlanError::OutOfBounds {
            len: 8,
            limit: 56,
            ..
        }
    ));

    let mut plan = synthetic_plan();
    if let Some(Op::KernelLaunch(launch)) = plan.ops.get_mut(0) {
        launch.kernel_key = "missing_kernel".into();
    }
    assert!(matches!(
        parse_err(&plan.to_bytes()),
        PlanError::UnknownKernel { .. }
    ));
}

#[test]
fn nested_branch_sizes_must_match_their_contents() {
    let bytes = synthetic_plan().to_bytes();
    let while_at = top_level_op_offsets(&bytes)[5];
    // APICCondRecord: header 8, cond region 4, pad 4, cond offset 8, then branch_a_size,
    // branch_a_op_count, branch_b_size, branch_b_op_count.
    let a_size = while_at + 24;
    let a_count = while_at + 28;

    let mut wrong_count = bytes.clone();
    put_u32(&mut wrong_count, a_count, 0);
    let err = parse_err(&wrong_count);
    assert!(matches!(err, PlanError::SizeMismatch { .. }), "{err}");
    assert!(
        err.to_string().contains("body branch of 0 operations"),
        "{err}"
    );

    let mut too_many = bytes.clone();
    put_u32(&mut too_many, a_count, 2);
    assert!(matches!(parse_err(&too_many), PlanError::Truncated { .. }));

    let mut too_big = bytes.clone();
    let size = read_u32(&bytes, a_size);
    put_u32(&mut too_big, a_size, size + 8);
    assert!(matches!(parse_err(&too_big), PlanError::Truncated { .. }));

    let mut too_small = bytes.clone();
    put_u32(&mut too_small, a_size, size - 8);
    assert!(parse_err(&too_small).to_string().contains("while"));

    // A WHILE has no second branch.
    let mut second = bytes;
    put_u32(&mut second, while_at + 36, 1);
    assert!(matches!(parse_err(&second), PlanError::Malformed { .. }));
}

#[test]
fn record_sizes_and_op_kinds_are_checked() {
    let bytes = synthetic_plan().to_bytes();
    let memset_at = top_level_op_offsets(&bytes)[1];

    let mut unknown = bytes.clone();
    put_u32(&mut unknown, memset_at, 3); // the reserved device-to-host copy
    assert!(matches!(
        parse_err(&unknown),
        PlanError::UnknownOpKind { kind: 3, .. }
    ));
    put_u32(&mut unknown, memset_at, 99);
    let err = parse_err(&unknown);
    assert!(matches!(err, PlanError::UnknownOpKind { kind: 99, .. }));
    assert!(
        err.to_string()
            .starts_with(&format!("operation 1 at byte {memset_at}")),
        "{err}"
    );

    let mut wrong_size = bytes.clone();
    put_u32(&mut wrong_size, memset_at + 4, 40);
    assert!(matches!(
        parse_err(&wrong_size),
        PlanError::SizeMismatch {
            declared: 40,
            actual: 32,
            ..
        }
    ));

    let mut tiny = bytes;
    put_u32(&mut tiny, memset_at + 4, 4);
    assert!(matches!(parse_err(&tiny), PlanError::SizeMismatch { .. }));
}

#[test]
fn nesting_deeper_than_the_limit_is_refused() {
    let nest = |depth: usize| {
        let mut plan = synthetic_plan();
        let mut op = Op::Memset(plan_support_memset());
        for _ in 0..depth {
            op = Op::While(WhileOp {
                cond: plan_support::at(3, 0),
                body: vec![op],
            });
        }
        plan.ops = vec![op];
        plan
    };
    let ok = nest(plan::MAX_NESTING_DEPTH);
    assert_eq!(Plan::parse(&ok.to_bytes()).ok(), Some(ok));
    let err = parse_err(&nest(plan::MAX_NESTING_DEPTH + 1).to_bytes());
    assert!(matches!(err, PlanError::TooDeep { .. }), "{err}");
}

fn plan_support_memset() -> plan::Memset {
    plan::Memset {
        dst: plan_support::at(2, 0),
        value: 0,
        size: 16,
    }
}

#[test]
fn garbage_and_oversized_zstd_streams_are_refused() {
    let mut garbage = vec![0x28, 0xb5, 0x2f, 0xfd];
    let mut rng = Rng::new(7);
    garbage.extend((0..200).map(|_| rng.next() as u8));
    assert!(matches!(
        load_plan(&garbage),
        Err(PlanError::Decompress { .. })
    ));

    let raw = synthetic_plan().to_bytes();
    let packed = plan::compress(&raw).map_err(|e| e.to_string());
    let packed = packed.as_deref().unwrap_or_default();
    assert!(load_plan(packed).is_ok());
    let limit = raw.len() as u64 - 1;
    assert!(matches!(
        load_plan_with_limit(packed, limit),
        Err(PlanError::DecompressedTooLarge { .. })
    ));

    // A frame that does not state its size is stopped while decompressing.
    let mut encoder = match zstd::stream::Encoder::new(Vec::new(), 3) {
        Ok(encoder) => encoder,
        Err(err) => panic!("{err}"),
    };
    assert!(encoder.include_contentsize(false).is_ok());
    assert!(std::io::Write::write_all(&mut encoder, &vec![0u8; 1 << 20]).is_ok());
    let unsized_frame = encoder.finish().unwrap_or_default();
    assert_eq!(
        zstd::zstd_safe::get_frame_content_size(&unsized_frame).ok(),
        Some(None)
    );
    assert!(matches!(
        load_plan_with_limit(&unsized_frame, 1000),
        Err(PlanError::DecompressedTooLarge { limit: 1000 })
    ));
}

#[test]
fn plan_info_must_be_valid_json() {
    let mut plan = synthetic_plan();
    plan.info = Some(PlanInfo {
        name: "step".into(),
        nworld: 4,
        physics: serde_json::Map::new(),
    });
    let mut bytes = plan.to_bytes();
    let info_at = section_offset(&bytes, 3);
    bytes[info_at] = b'[';
    assert!(matches!(parse_err(&bytes), PlanError::InfoJson { .. }));
}

#[test]
fn random_byte_flips_never_panic() {
    let mut rng = Rng::new(0x5eed);
    let ops_start = section_offset(FIXTURE, 2);
    let mut outcomes = [0usize; 2];
    for i in 0..2000 {
        let mut bytes = FIXTURE.to_vec();
        for _ in 0..1 + rng.below(4) {
            // Half the flips land in the header, table and metadata, half anywhere after.
            let pos = if i % 2 == 0 {
                rng.below(ops_start)
            } else {
                ops_start + rng.below(bytes.len() - ops_start)
            };
            bytes[pos] ^= 1 << rng.below(8);
        }
        outcomes[usize::from(Plan::parse(&bytes).is_ok())] += 1;
    }
    // Flips inside initial data are harmless; flips in structure are caught.
    assert!(
        outcomes[0] > 0 && outcomes[1] > 0,
        "errors/oks: {outcomes:?}"
    );

    let synthetic = every_kind_plan().to_bytes();
    for _ in 0..2000 {
        let mut bytes = synthetic.clone();
        let pos = rng.below(bytes.len());
        bytes[pos] = rng.next() as u8;
        let _ = Plan::parse(&bytes);
    }
}
