//! GPU tests of the CUDA layer. Run on a machine with an NVIDIA GPU and driver:
//! `cargo test --features gpu --test gpu_cuda -- --nocapture` (tests run in parallel threads,
//! each with its own `Gpu` handle and stream, which the layer must allow: captures on one
//! thread while others allocate, copy and free).
//!
//! The kernels are hand-written PTX in `tests/fixtures/test_kernels.ptx`.
#![cfg(feature = "gpu")]

use std::collections::BTreeMap;
use std::sync::Arc;

use instantmimic::cuda::{
    AddressSource, ArgLayout, CudaError, DeviceMemory, DeviceRange, Function, Gpu, KernelArgs,
    Module, NvtxRange, PtxIsa, Stream,
};

const KERNELS_PTX: &str = include_str!("fixtures/test_kernels.ptx");
/// Warp's own PTX (.version 9.4, trailing NUL): see fixtures/README.md.
const WARP_PTX: &[u8] = include_bytes!("fixtures/warp_fill_index_scaled.sm75.ptx");

struct Kernels {
    gpu: Gpu,
    module: Module,
    fill_scaled: Function,
    add_u32: Function,
    decrement_i32: Function,
}

fn setup() -> Kernels {
    let gpu = Gpu::open(0).expect("opening GPU 0");
    let module = gpu
        .load_ptx("test_kernels", KERNELS_PTX.as_bytes())
        .expect("loading test_kernels.ptx");
    Kernels {
        fill_scaled: module.function("fill_scaled").unwrap(),
        add_u32: module.function("add_u32").unwrap(),
        decrement_i32: module.function("decrement_i32").unwrap(),
        module,
        gpu,
    }
}

/// The whole of `memory`, as the stream operations and kernel arguments take it.
fn whole(memory: &Arc<DeviceMemory>) -> DeviceRange {
    DeviceRange::whole(memory)
}

/// Bytes `[offset, offset + len)` of `memory`.
fn range(memory: &Arc<DeviceMemory>, offset: usize, len: usize) -> Result<DeviceRange, CudaError> {
    DeviceRange::new(memory, offset, len)
}

fn fill_args(out: &Arc<DeviceMemory>, n: u32, scale: f32) -> KernelArgs {
    // { u64 out; u32 n; f32 scale }: offsets 0, 8, 12.
    let layout = ArgLayout::trusting(
        AddressSource::KernelBeside,
        vec![(0, 8), (8, 4), (12, 4)],
        [0],
    )
    .unwrap();
    let mut args = KernelArgs::new(layout);
    args.write_address(0, &whole(out)).unwrap();
    args.write(8, &n.to_ne_bytes()).unwrap();
    args.write(12, &scale.to_ne_bytes()).unwrap();
    args
}

fn add_args(counter: &Arc<DeviceMemory>, value: u32) -> KernelArgs {
    // struct { u64 ptr; u32 value; u32 pad }
    let mut args = KernelArgs::new(
        ArgLayout::trusting(AddressSource::KernelBeside, vec![(0, 16)], [0]).unwrap(),
    );
    args.write_address(0, &whole(counter)).unwrap();
    args.write(8, &value.to_ne_bytes()).unwrap();
    args
}

impl Kernels {
    fn add(&self, s: &Stream, counter: &Arc<DeviceMemory>, value: u32) -> Result<(), CudaError> {
        s.launch(
            &self.add_u32,
            [1, 1, 1],
            [1, 1, 1],
            0,
            &add_args(counter, value),
        )
    }

    fn decrement(&self, s: &Stream, flag: &Arc<DeviceMemory>) -> Result<(), CudaError> {
        let mut args = KernelArgs::new(ArgLayout::trusting(
            AddressSource::KernelBeside,
            vec![(0, 8)],
            [0],
        )?);
        args.write_address(0, &whole(flag))?;
        s.launch(&self.decrement_i32, [1, 1, 1], [1, 1, 1], 0, &args)
    }
}

fn read_u32(memory: &DeviceMemory) -> u32 {
    let mut bytes = [0u8; 4];
    memory.copy_to_host(0, &mut bytes).unwrap();
    u32::from_ne_bytes(bytes)
}

fn read_i32(memory: &DeviceMemory) -> i32 {
    read_u32(memory) as i32
}

fn write_i32(memory: &DeviceMemory, value: i32) {
    memory.copy_from_host(0, &value.to_ne_bytes()).unwrap();
}

fn f32s(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_ne_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn u32s(bytes: &[u8]) -> Vec<u32> {
    bytes
        .chunks_exact(4)
        .map(|c| u32::from_ne_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn count(counts: &BTreeMap<String, usize>, kind: &str) -> usize {
    counts.get(kind).copied().unwrap_or(0)
}

/// The same name and PTX load once per GPU (the HPO builds a trainer per trial on one `Gpu`);
/// other PTX or another name is another module, and the cached one still launches.
#[test]
fn loading_the_same_ptx_again_returns_the_loaded_module() {
    let k = setup();
    let again = k
        .gpu
        .clone()
        .load_ptx("test_kernels", KERNELS_PTX.as_bytes())
        .unwrap();
    assert!(again.is_same_module(&k.module));
    let renamed = k
        .gpu
        .load_ptx("test_kernels_2", KERNELS_PTX.as_bytes())
        .unwrap();
    assert!(!renamed.is_same_module(&k.module));
    let other = k.gpu.load_ptx("warp", WARP_PTX).unwrap();
    assert!(!other.is_same_module(&k.module));
    let out = k.gpu.alloc_zeroed(4 * 4).map(Arc::new).unwrap();
    let fill = again.function("fill_scaled").unwrap();
    let s = k.gpu.stream();
    s.launch(&fill, [1, 1, 1], [4, 1, 1], 0, &fill_args(&out, 4, 2.0))
        .unwrap();
    s.synchronize().unwrap();
    println!("a second load of test_kernels returned the first module, which launches");
}

#[test]
fn a_launch_needs_every_address_slot_filled_and_the_drivers_parameters() {
    let k = setup();
    let s = k.gpu.stream();
    let out = k.gpu.alloc_zeroed(4 * 4).map(Arc::new).unwrap();
    // fill_scaled(u64 out, u32 n, f32 scale): the address slot left unset.
    let layout = ArgLayout::trusting(
        AddressSource::KernelBeside,
        vec![(0, 8), (8, 4), (12, 4)],
        [0],
    )
    .unwrap();
    let mut unset = KernelArgs::new(layout.clone());
    unset.write(8, &4u32.to_ne_bytes()).unwrap();
    let err = s
        .launch(&k.fill_scaled, [1, 1, 1], [4, 1, 1], 0, &unset)
        .unwrap_err();
    assert!(err.to_string().contains("never written"), "{err}");
    // A plain write cannot put an integer where the kernel reads the address.
    let err = unset.write(0, &0x1000u64.to_ne_bytes()).unwrap_err();
    assert!(err.to_string().contains("device address"), "{err}");
    // The same 16 bytes described as other parameters than the driver reports.
    let mut other = KernelArgs::new(
        ArgLayout::trusting(AddressSource::KernelBeside, vec![(0, 8), (8, 8)], [0]).unwrap(),
    );
    other.write_address(0, &whole(&out)).unwrap();
    let err = s
        .launch(&k.fill_scaled, [1, 1, 1], [4, 1, 1], 0, &other)
        .unwrap_err();
    assert!(
        err.to_string().contains("the driver reports parameters"),
        "{err}"
    );
    s.launch(
        &k.fill_scaled,
        [1, 1, 1],
        [4, 1, 1],
        0,
        &fill_args(&out, 4, 2.0),
    )
    .unwrap();
    s.synchronize().unwrap();
}

#[test]
fn open_reports_device_facts_and_bad_ordinals() {
    let gpu = Gpu::open(0).unwrap();
    let info = gpu.info();
    assert!(!info.name.is_empty());
    assert_eq!(info.ordinal, 0);
    assert!(
        info.compute_capability.0 >= 7,
        "{:?}",
        info.compute_capability
    );
    assert!(info.sm_count > 0);
    assert!(info.total_memory_bytes > 1 << 30);
    assert!(info.driver_version >= instantmimic::cuda::MIN_DRIVER_VERSION);
    assert_eq!(info.max_ptx_isa, PtxIsa::for_driver(info.driver_version));
    let (free, total) = gpu.memory_info().unwrap();
    assert!(free > 0 && free <= total);
    println!("opened {info:?}; {free} of {total} bytes free");

    let err = Gpu::open(9999).unwrap_err();
    assert!(
        matches!(err, CudaError::NoDevice { ordinal: 9999, count } if count >= 1),
        "{err}"
    );
    println!("ordinal 9999: {err}");
}

#[test]
fn packed_argument_launch_writes_expected_values() {
    let k = setup();
    let s = k.gpu.stream();
    let n = 1000u32; // not a multiple of the block size: the bounds check in the kernel matters
    let out = k
        .gpu
        .alloc_zeroed((n as usize + 24) * 4)
        .map(Arc::new)
        .unwrap();
    s.launch(
        &k.fill_scaled,
        [n.div_ceil(128), 1, 1],
        [128, 1, 1],
        0,
        &fill_args(&out, n, 0.5),
    )
    .unwrap();
    s.synchronize().unwrap();
    let values = f32s(&out.to_vec().unwrap());
    for (i, v) in values.iter().enumerate().take(n as usize) {
        assert_eq!(*v, i as f32 * 0.5, "out[{i}]");
    }
    assert!(
        values[n as usize..].iter().all(|v| *v == 0.0),
        "the kernel wrote past n"
    );
    println!("fill_scaled: {n} values i*0.5 correct, 24 guard values untouched");
    assert_eq!(k.fill_scaled.param_layout(), [(0, 8), (8, 4), (12, 4)]);
    assert_eq!(k.add_u32.param_layout(), [(0, 16)]);
    assert_eq!(k.decrement_i32.param_bytes(), 8);

    let err = s
        .launch(
            &k.fill_scaled,
            [0, 1, 1],
            [128, 1, 1],
            0,
            &fill_args(&out, n, 1.0),
        )
        .unwrap_err();
    assert!(matches!(err, CudaError::InvalidArgument { .. }), "{err}");
    println!("grid with a zero dimension: {err}");
}

#[test]
fn ptx_version_above_the_driver_is_lowered_and_a_trailing_nul_stripped() {
    let gpu = Gpu::open(0).unwrap();
    let too_new = KERNELS_PTX.replace(".version 8.0", ".version 9.9");
    assert_ne!(too_new, KERNELS_PTX);
    let mut bytes = too_new.into_bytes();
    bytes.push(0);
    let module = gpu.load_ptx("test_kernels_v99", &bytes).unwrap();
    let fill = module.function("fill_scaled").unwrap();
    let out = gpu.alloc_zeroed(64 * 4).map(Arc::new).unwrap();
    gpu.stream()
        .launch(&fill, [1, 1, 1], [64, 1, 1], 0, &fill_args(&out, 64, 2.0))
        .unwrap();
    gpu.stream().synchronize().unwrap();
    let mut last = [0u8; 4];
    out.copy_to_host(63 * 4, &mut last).unwrap();
    assert_eq!(f32::from_ne_bytes(last), 126.0);
    println!(
        ".version 9.9 + trailing NUL loaded as {} and ran",
        gpu.info().max_ptx_isa
    );
}

/// Packs Warp's ABI for `fill_index_scaled(out: array(float32), scale: float32)` over `n`
/// elements: `launch_bounds_t<1> { u32 shape[1]; size_t size; size_t coord_mult }`, then
/// `array_t<float> { float* data; float* grad; int shape[4]; int strides[4]; int ndim; int flags }`,
/// then the float.
fn warp_fill_args(out: &Arc<DeviceMemory>, n: u32, scale: f32) -> KernelArgs {
    let mut args = Vec::with_capacity(84);
    args.extend_from_slice(&n.to_ne_bytes());
    args.extend_from_slice(&[0; 4]);
    args.extend_from_slice(&u64::from(n).to_ne_bytes());
    args.extend_from_slice(&1u64.to_ne_bytes());
    // The array's data pointer (byte 24), written below from the range; grad null.
    args.extend_from_slice(&0u64.to_ne_bytes());
    args.extend_from_slice(&0u64.to_ne_bytes());
    for dim in [n as i32, 0, 0, 0] {
        args.extend_from_slice(&dim.to_ne_bytes());
    }
    for stride in [4i32, 0, 0, 0] {
        args.extend_from_slice(&stride.to_ne_bytes());
    }
    args.extend_from_slice(&1i32.to_ne_bytes());
    args.extend_from_slice(&0i32.to_ne_bytes());
    args.extend_from_slice(&scale.to_ne_bytes());
    // The array's data and grad pointers are address slots; grad stays null.
    let layout = ArgLayout::trusting(
        AddressSource::KernelBeside,
        vec![(0, 24), (24, 56), (80, 4)],
        [24, 32],
    )
    .unwrap();
    let mut args = KernelArgs::with_bytes(layout, args).unwrap();
    args.write_address(24, &whole(out)).unwrap();
    args.write_null(32).unwrap();
    args
}

#[test]
fn warp_ptx_loads_and_runs_with_its_packed_abi() {
    let gpu = Gpu::open(0).unwrap();
    let s = gpu.stream();
    let module = gpu.load_ptx("wp_fill_index_scaled", WARP_PTX).unwrap();
    let forward = module
        .function("fill_index_scaled_91d0906e_cuda_kernel_forward")
        .unwrap();
    assert_eq!(forward.param_layout(), [(0, 24), (24, 56), (80, 4)]);
    let n = 3000u32;
    let out = gpu.alloc_zeroed(n as usize * 4 + 64).map(Arc::new).unwrap();
    let graph = s
        .capture(|s| {
            s.launch(
                &forward,
                [n.div_ceil(256), 1, 1],
                [256, 1, 1],
                0,
                &warp_fill_args(&out, n, 0.25),
            )
        })
        .unwrap();
    for _ in 0..2 {
        graph.launch(s).unwrap();
    }
    s.synchronize().unwrap();
    let values = f32s(&out.to_vec().unwrap());
    for (i, v) in values.iter().enumerate().take(n as usize) {
        assert_eq!(*v, i as f32 * 0.25, "out[{i}]");
    }
    assert!(
        values[n as usize..].iter().all(|v| *v == 0.0),
        "wrote past the array"
    );
    println!(
        "Warp PTX 9.4 (+NUL) loaded on a {} driver; 84-byte packed ABI launch in a graph wrote {n} values",
        gpu.info().max_ptx_isa
    );
}

/// A preload readies the modules for `load_ptx` (in this test binary, which starts no helper
/// processes, by loading the largest), and a bad largest module fails it with its name.
#[test]
fn preloaded_modules_load_and_a_bad_one_is_named() {
    let gpu = Gpu::open(0).unwrap();
    let modules: Vec<(&str, &[u8])> = vec![
        ("preloaded_kernels", KERNELS_PTX.as_bytes()),
        ("preloaded_warp", WARP_PTX),
    ];
    gpu.preload_ptx(&modules).unwrap();
    let kernels = gpu
        .load_ptx("preloaded_kernels", KERNELS_PTX.as_bytes())
        .unwrap();
    let again = gpu
        .load_ptx("preloaded_kernels", KERNELS_PTX.as_bytes())
        .unwrap();
    assert!(kernels.is_same_module(&again));
    let out = gpu.alloc_zeroed(4 * 4).map(Arc::new).unwrap();
    let fill = kernels.function("fill_scaled").unwrap();
    let s = gpu.stream();
    s.launch(&fill, [1, 1, 1], [4, 1, 1], 0, &fill_args(&out, 4, 2.0))
        .unwrap();
    s.synchronize().unwrap();

    let garbage = vec![b'x'; KERNELS_PTX.len() + WARP_PTX.len()];
    let bad: Vec<(&str, &[u8])> = vec![
        ("preload_good", KERNELS_PTX.as_bytes()),
        ("preload_garbage", &garbage),
    ];
    let err = gpu.preload_ptx(&bad).unwrap_err();
    assert!(err.to_string().contains("preload_garbage"), "{err}");
}

#[test]
fn bad_ptx_gives_errors_that_name_the_module() {
    let gpu = Gpu::open(0).unwrap();
    let err = gpu
        .load_ptx("garbage_module", b"this is not PTX at all")
        .unwrap_err();
    assert!(err.to_string().contains("garbage_module"), "{err}");
    println!("garbage: {err}");

    let broken = ".version 8.0\n.target sm_75\n.address_size 64\n.visible .entry broken()\n{\n\tbogus.instruction %r1;\n\tret;\n}\n";
    let err = gpu
        .load_ptx("broken_module", broken.as_bytes())
        .unwrap_err();
    match &err {
        CudaError::ModuleLoad { module, log, .. } => {
            assert_eq!(module, "broken_module");
            assert!(!log.trim().is_empty(), "the JIT log is empty");
        }
        other => panic!("expected ModuleLoad, got {other:?}"),
    }
    assert!(
        err.to_string().contains("broken_module") && err.to_string().contains("cuModuleLoadDataEx")
    );
    println!("syntax error: {err}");

    let err = gpu
        .load_ptx("nul_module", b".version 8.0\n\0.target sm_75\n")
        .unwrap_err();
    assert!(err.to_string().contains("nul_module"), "{err}");

    let module = gpu
        .load_ptx("test_kernels", KERNELS_PTX.as_bytes())
        .unwrap();
    let err = module.function("no_such_kernel").unwrap_err();
    assert!(
        err.to_string().contains("no_such_kernel")
            && err.to_string().contains("CUDA_ERROR_NOT_FOUND"),
        "{err}"
    );
    println!("missing entry: {err}");
}

#[test]
fn memsets_and_copies_land_where_asked() {
    let k = setup();
    let s = k.gpu.stream();
    let memory = k.gpu.alloc_zeroed(64).map(Arc::new).unwrap();
    let at = |offset: usize, len: usize| range(&memory, offset, len).unwrap();
    s.fill_u8(&at(1, 3), 0xAB).unwrap();
    s.fill_u16(&at(8, 4), 0xBEEF).unwrap();
    s.fill_u32(&at(16, 12), 0xDEAD_BEEF).unwrap();
    s.copy(&at(40, 12), &at(16, 12)).unwrap();
    let pinned = Arc::new(k.gpu.alloc_pinned(16).unwrap());
    pinned.write(4, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    s.copy_from_pinned(&at(56, 8), &pinned, 4).unwrap();
    s.synchronize().unwrap();

    let mut expected = vec![0u8; 64];
    expected[1..4].fill(0xAB);
    for i in 0..2 {
        expected[8 + 2 * i..10 + 2 * i].copy_from_slice(&0xBEEFu16.to_ne_bytes());
    }
    for i in 0..3 {
        expected[16 + 4 * i..20 + 4 * i].copy_from_slice(&0xDEAD_BEEFu32.to_ne_bytes());
        expected[40 + 4 * i..44 + 4 * i].copy_from_slice(&0xDEAD_BEEFu32.to_ne_bytes());
    }
    expected[56..64].copy_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
    assert_eq!(memory.to_vec().unwrap(), expected);
    println!("memset u8/u16/u32, dtod and htod wrote exactly the expected 64 bytes");

    memory.copy_from_host(60, &[9, 9, 9, 9]).unwrap();
    let mut tail = [0u8; 4];
    memory.copy_to_host(60, &mut tail).unwrap();
    assert_eq!(tail, [9; 4]);

    let errors = [
        s.fill_u16(&at(1, 2), 0).unwrap_err(),
        s.fill_u32(&at(2, 4), 0).unwrap_err(),
        s.fill_u32(&at(4, 6), 0).unwrap_err(),
        s.fill_u32_strided(&at(0, 8), 8, 0, 2).unwrap_err(),
        s.copy(&at(0, 8), &at(4, 8)).unwrap_err(),
        s.copy(&at(0, 8), &at(16, 4)).unwrap_err(),
        range(&memory, 60, 8).unwrap_err(),
        memory.copy_to_host(60, &mut [0u8; 8]).unwrap_err(),
        memory.copy_from_host(usize::MAX, &[1]).unwrap_err(),
        s.copy_from_pinned(&at(0, 8), &pinned, 12).unwrap_err(),
        pinned.write(15, &[1, 2]).unwrap_err(),
    ];
    for err in &errors {
        assert!(
            matches!(
                err,
                CudaError::InvalidArgument { .. } | CudaError::OutOfBounds { .. }
            ),
            "{err}"
        );
        println!("rejected: {err}");
    }
    let empty = k.gpu.alloc_zeroed(0).map(Arc::new).unwrap();
    assert_eq!((whole(&empty).len(), empty.len()), (0, 0));
    s.fill_u8(&whole(&empty), 1).unwrap();
}

#[test]
fn event_timing_is_positive() {
    let k = setup();
    let s = k.gpu.stream();
    let n = 1 << 22;
    let out = k.gpu.alloc_zeroed(n * 4).map(Arc::new).unwrap();
    let start = k.gpu.new_event().unwrap();
    let end = k.gpu.new_event().unwrap();
    start.record(s).unwrap();
    for _ in 0..20 {
        s.launch(
            &k.fill_scaled,
            [(n as u32).div_ceil(256), 1, 1],
            [256, 1, 1],
            0,
            &fill_args(&out, n as u32, 1.0),
        )
        .unwrap();
    }
    end.record(s).unwrap();
    let ms = start.elapsed_ms(&end).unwrap();
    assert!(ms > 0.0, "{ms} ms");
    println!(
        "20 launches over {n} floats: {ms:.3} ms ({:.1} GB/s written)",
        20.0 * (n * 4) as f64 / (ms as f64 * 1e6)
    );
}

#[test]
fn captured_graph_replays_and_keeps_its_module_alive() {
    let k = setup();
    let gpu = k.gpu.clone();
    let s = gpu.stream();
    let counter = gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let scratch = gpu.alloc_zeroed(64).map(Arc::new).unwrap();
    let graph = s
        .capture(|s| -> Result<(), CudaError> {
            k.add(s, &counter, 1)?;
            k.add(s, &counter, 2)?;
            k.add(s, &counter, 3)?;
            s.fill_u32(&range(&scratch, 0, 32)?, 7)?;
            s.copy(&range(&scratch, 32, 32)?, &range(&scratch, 0, 32)?)?;
            Ok(())
        })
        .unwrap();
    assert_eq!(read_u32(&counter), 0, "capture must not run the work");
    // The graph holds one reference to each allocation it addresses.
    assert_eq!(Arc::strong_count(&counter), 2);
    assert_eq!(Arc::strong_count(&scratch), 2);
    let counts = graph.node_counts().unwrap();
    assert_eq!(count(&counts, "kernel"), 3, "{counts:?}");
    assert_eq!(count(&counts, "memset"), 1, "{counts:?}");
    assert_eq!(count(&counts, "memcpy"), 1, "{counts:?}");
    assert_eq!(count(&counts, "host"), 0, "{counts:?}");

    // The graph holds the module: dropping every handle we have must not unload its code.
    drop(k);
    graph.upload(s).unwrap();
    for _ in 0..5 {
        graph.launch(s).unwrap();
    }
    s.synchronize().unwrap();
    assert_eq!(read_u32(&counter), 30);
    assert!(u32s(&scratch.to_vec().unwrap()).iter().all(|v| *v == 7));
    drop(graph);
    assert_eq!(
        Arc::strong_count(&scratch),
        1,
        "the graph let go of its memory"
    );
    println!(
        "graph {counts:?} replayed 5 times: counter 30, memset+memcpy filled 64 bytes; module kept alive"
    );
}

#[test]
fn pinned_source_is_read_at_each_replay() {
    let gpu = Gpu::open(0).unwrap();
    let s = gpu.stream();
    let dst = gpu.alloc_zeroed(8).map(Arc::new).unwrap();
    let pinned = Arc::new(gpu.alloc_pinned(8).unwrap());
    let graph = s
        .capture(|s| s.copy_from_pinned(&whole(&dst), &pinned, 0))
        .unwrap();
    assert_eq!(
        Arc::strong_count(&pinned),
        2,
        "the graph keeps the pinned source"
    );
    for round in 1u64..=3 {
        pinned.write(0, &(round * 1111).to_ne_bytes()).unwrap();
        graph.launch(s).unwrap();
        s.synchronize().unwrap();
        let mut got = [0u8; 8];
        dst.copy_to_host(0, &mut got).unwrap();
        assert_eq!(u64::from_ne_bytes(got), round * 1111);
    }
    println!("H2D copy node uploaded the pinned bytes as they were at each of 3 launches");
}

#[test]
fn capture_while_runs_the_body_exactly_cond_times() {
    let k = setup();
    let s = k.gpu.stream();
    let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let cond = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let graph = s
        .capture(|s| {
            s.capture_while(&whole(&cond), |s| {
                k.add(s, &counter, 1)?;
                k.decrement(s, &cond)
            })
        })
        .unwrap();
    let counts = graph.node_counts().unwrap();
    // Outside: the handle-setting kernel and the node; inside: add, decrement, handle-setting.
    assert_eq!(count(&counts, "conditional"), 1, "{counts:?}");
    assert_eq!(count(&counts, "kernel"), 4, "{counts:?}");
    assert_eq!(count(&counts, "host"), 0, "{counts:?}");
    for n in [5, 0, 1, 37] {
        counter.copy_from_host(0, &0u32.to_ne_bytes()).unwrap();
        write_i32(&cond, n);
        graph.launch(s).unwrap();
        s.synchronize().unwrap();
        assert_eq!(read_u32(&counter), n as u32, "cond started at {n}");
        assert_eq!(read_i32(&cond), 0);
    }
    println!("WHILE {counts:?}: body ran exactly 5, 0, 1 and 37 times for cond 5, 0, 1, 37");
}

#[test]
fn nested_while_loops_multiply() {
    let k = setup();
    let s = k.gpu.stream();
    let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let outer = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let inner = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let graph = s
        .capture(|s| {
            s.capture_while(&whole(&outer), |s| {
                s.fill_u32(&whole(&inner), 4)?;
                s.capture_while(&whole(&inner), |s| {
                    k.add(s, &counter, 1)?;
                    k.decrement(s, &inner)
                })?;
                k.decrement(s, &outer)
            })?;
            k.add(s, &counter, 1000)
        })
        .unwrap();
    let counts = graph.node_counts().unwrap();
    assert_eq!(count(&counts, "conditional"), 2, "{counts:?}");
    assert_eq!(count(&counts, "memset"), 1, "{counts:?}");
    write_i32(&outer, 3);
    graph.launch(s).unwrap();
    s.synchronize().unwrap();
    assert_eq!(
        read_u32(&counter),
        3 * 4 + 1000,
        "work after the loop must run once, after it"
    );
    println!("nested WHILE {counts:?}: 3 x 4 inner iterations, then the trailing kernel");
}

#[test]
fn capture_if_takes_the_right_branch() {
    let k = setup();
    let s = k.gpu.stream();
    let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let cond = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let run = |graph: &instantmimic::cuda::Graph, flag: i32| -> u32 {
        counter.copy_from_host(0, &0u32.to_ne_bytes()).unwrap();
        write_i32(&cond, flag);
        graph.launch(s).unwrap();
        s.synchronize().unwrap();
        read_u32(&counter)
    };

    // THEN also clears the flag: ELSE must still not run in the same launch.
    let both = s
        .capture(|s| {
            s.capture_if(
                &whole(&cond),
                Some(&mut |s: &Stream| {
                    k.add(s, &counter, 1)?;
                    s.fill_u32(&whole(&cond), 0)
                }),
                Some(&mut |s: &Stream| k.add(s, &counter, 100)),
            )
        })
        .unwrap();
    assert_eq!(run(&both, 1), 1);
    assert_eq!(read_i32(&cond), 0);
    assert_eq!(run(&both, 0), 100);
    assert_eq!(run(&both, 7), 1);
    assert_eq!(run(&both, -1), 1);
    let counts = both.node_counts().unwrap();
    assert_eq!(count(&counts, "conditional"), 2, "{counts:?}");
    assert_eq!(count(&counts, "host"), 0, "{counts:?}");
    println!("IF/ELSE {counts:?}: cond 1, 7, -1 -> then only; 0 -> else only");

    let then_only = s
        .capture(|s| {
            s.capture_if(
                &whole(&cond),
                Some(&mut |s: &Stream| k.add(s, &counter, 1)),
                None,
            )
        })
        .unwrap();
    assert_eq!(run(&then_only, 1), 1);
    assert_eq!(run(&then_only, 0), 0);

    let else_only = s
        .capture(|s| {
            s.capture_if(
                &whole(&cond),
                None,
                Some(&mut |s: &Stream| k.add(s, &counter, 100)),
            )
        })
        .unwrap();
    assert_eq!(run(&else_only, 0), 100);
    assert_eq!(run(&else_only, 1), 0);
    assert_eq!(count(&else_only.node_counts().unwrap(), "conditional"), 1);
    println!("IF only: 1 -> 1, 0 -> 0; ELSE only: 0 -> 100, 1 -> 0");

    let none = s
        .capture(|s| s.capture_if::<CudaError>(&whole(&cond), None, None))
        .unwrap();
    assert!(none.node_counts().unwrap().is_empty());
}

#[test]
fn conditional_calls_outside_a_capture_are_errors() {
    let k = setup();
    let s = k.gpu.stream();
    let cond = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    // Loads the conditional kernels, so the next errors are about capturing, not loading.
    drop(s.capture(|_| Ok::<(), CudaError>(())).unwrap());
    let err = s
        .capture_while(&whole(&cond), |_| Ok::<(), CudaError>(()))
        .unwrap_err();
    assert!(matches!(err, CudaError::NotCapturing { .. }), "{err}");
    let err = s
        .capture_if::<CudaError>(&whole(&cond), Some(&mut |_: &Stream| Ok(())), None)
        .unwrap_err();
    assert!(matches!(err, CudaError::NotCapturing { .. }), "{err}");
    let err = s
        .capture(|s| s.capture(|_| Ok::<(), CudaError>(())).map(drop))
        .unwrap_err();
    assert!(matches!(err, CudaError::AlreadyCapturing), "{err}");
    println!("outside capture: {err}");
}

#[derive(Debug)]
enum TestError {
    Cuda(CudaError),
    Planned(&'static str),
}

impl From<CudaError> for TestError {
    fn from(err: CudaError) -> Self {
        TestError::Cuda(err)
    }
}

fn assert_stream_usable(k: &Kernels, s: &Stream) {
    assert!(!s.is_capturing().unwrap());
    let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    k.add(s, &counter, 5).unwrap();
    s.synchronize().unwrap();
    assert_eq!(read_u32(&counter), 5);
    let graph = s.capture(|s| k.add(s, &counter, 1)).unwrap();
    graph.launch(s).unwrap();
    s.synchronize().unwrap();
    assert_eq!(read_u32(&counter), 6);
}

#[test]
fn failed_captures_leave_the_stream_usable() {
    let k = setup();
    let s = k.gpu.stream();
    let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let cond = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();

    let err = s
        .capture(|s| -> Result<(), TestError> {
            k.add(s, &counter, 1)?;
            Err(TestError::Planned("closure failed"))
        })
        .unwrap_err();
    assert!(
        matches!(err, TestError::Planned("closure failed")),
        "{err:?}"
    );
    assert_stream_usable(&k, s);
    assert_eq!(
        read_u32(&counter),
        0,
        "the abandoned capture must not have run"
    );
    println!("closure error: returned as is, stream usable");

    let err = s
        .capture(|s| -> Result<(), TestError> {
            k.add(s, &counter, 1)?;
            s.capture_while(&whole(&cond), |s| -> Result<(), TestError> {
                k.add(s, &counter, 1)?;
                Err(TestError::Planned("body failed"))
            })?;
            k.add(s, &counter, 1)?;
            Ok(())
        })
        .unwrap_err();
    assert!(matches!(err, TestError::Planned("body failed")), "{err:?}");
    assert_stream_usable(&k, s);
    println!("error inside a WHILE body: returned as is, stream usable");

    let err = s
        .capture(|s| -> Result<(), TestError> {
            s.capture_if(
                &whole(&cond),
                Some(&mut |_: &Stream| Err(TestError::Planned("branch failed"))),
                None,
            )
        })
        .unwrap_err();
    assert!(
        matches!(err, TestError::Planned("branch failed")),
        "{err:?}"
    );
    assert_stream_usable(&k, s);

    // Host-synchronous memory calls inside a capture are refused before touching the stream.
    let err = s
        .capture(|s| -> Result<(), CudaError> {
            k.add(s, &counter, 1)?;
            counter.copy_to_host(0, &mut [0u8; 4])?;
            Ok(())
        })
        .unwrap_err();
    assert!(
        matches!(
            err,
            CudaError::InvalidArgument {
                operation: "DeviceMemory::copy_to_host",
                ..
            }
        ),
        "{err}"
    );
    let err = s.capture(|_| k.gpu.alloc_zeroed(16).map(drop)).unwrap_err();
    assert!(
        matches!(
            err,
            CudaError::InvalidArgument {
                operation: "Gpu::alloc_zeroed",
                ..
            }
        ),
        "{err}"
    );
    assert_stream_usable(&k, s);
    println!("copy/alloc inside capture: {err}; stream usable");

    // A call that is illegal during capture invalidates it; the error still comes back.
    let err = s
        .capture(|s| -> Result<(), TestError> {
            k.add(s, &counter, 1)?;
            s.synchronize()?;
            Ok(())
        })
        .unwrap_err();
    let TestError::Cuda(err) = err else {
        panic!("expected a CUDA error, got {err:?}")
    };
    assert!(matches!(err, CudaError::Driver { .. }), "{err}");
    assert_stream_usable(&k, s);
    assert_eq!(read_u32(&counter), 0, "no abandoned capture ran");
    println!("stream synchronize inside capture: {err}; stream usable");
}

#[test]
fn dynamic_shared_memory_above_48_kib_needs_the_attribute() {
    let k = setup();
    let s = k.gpu.stream();
    let smem = k.module.function("smem_neighbor").unwrap();
    let threads = 256u32;
    let bytes = 96 * 1024u32;
    let out = k
        .gpu
        .alloc_zeroed(threads as usize * 4)
        .map(Arc::new)
        .unwrap();
    // (u64 out, u32 bytes): 12 bytes, the exact parameter size.
    let mut args = KernelArgs::new(
        ArgLayout::trusting(AddressSource::KernelBeside, vec![(0, 8), (8, 4)], [0]).unwrap(),
    );
    args.write_address(0, &whole(&out)).unwrap();
    args.write(8, &bytes.to_ne_bytes()).unwrap();
    assert_eq!(smem.param_layout(), [(0, 8), (8, 4)]);
    let mut padded = KernelArgs::new(
        ArgLayout::trusting(AddressSource::KernelBeside, vec![(0, 8), (8, 8)], [0]).unwrap(),
    );
    padded.write_address(0, &whole(&out)).unwrap();
    padded.write(8, &bytes.to_ne_bytes()).unwrap();
    let err = s
        .launch(&smem, [1, 1, 1], [threads, 1, 1], 0, &padded)
        .unwrap_err();
    assert!(
        err.to_string().contains("takes 12 bytes") && err.to_string().contains("got 16"),
        "{err}"
    );
    println!("a 16-byte buffer for 12 bytes of parameters: {err}");
    let refused = s.launch(&smem, [1, 1, 1], [threads, 1, 1], bytes, &args);
    assert!(
        refused.is_err(),
        "a 96 KiB launch without the attribute was accepted"
    );
    println!("without the attribute: {}", refused.unwrap_err());
    smem.set_max_dynamic_shared_memory(bytes).unwrap();
    use cudarc::driver::sys::CUfunction_attribute as A;
    let allowed = smem
        .attribute(A::CU_FUNC_ATTRIBUTE_MAX_DYNAMIC_SHARED_SIZE_BYTES)
        .unwrap();
    assert_eq!(allowed, bytes as i32);
    s.launch(&smem, [1, 1, 1], [threads, 1, 1], bytes, &args)
        .unwrap();
    s.synchronize().unwrap();
    for (t, got) in u32s(&out.to_vec().unwrap()).into_iter().enumerate() {
        let t = t as u32;
        assert_eq!(got, 3 * ((t + 1) % threads) + 1, "thread {t}");
    }
    println!(
        "96 KiB of dynamic shared memory after set_max_dynamic_shared_memory: all {threads} values right"
    );
}

#[test]
fn handles_work_from_another_thread() {
    let k = setup();
    let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let ptr = counter.clone();
    let gpu = k.gpu.clone();
    let add = k.add_u32.clone();
    std::thread::spawn(move || {
        let s = gpu.new_stream().unwrap();
        s.launch(&add, [1, 1, 1], [1, 1, 1], 0, &add_args(&ptr, 9))
            .unwrap();
        let graph = s
            .capture(|s| s.launch(&add, [1, 1, 1], [1, 1, 1], 0, &add_args(&ptr, 1)))
            .unwrap();
        graph.launch(&s).unwrap();
        s.synchronize().unwrap();
    })
    .join()
    .unwrap();
    assert_eq!(read_u32(&counter), 10);
    println!("another thread launched and captured on its own stream of the shared context");
}

#[test]
fn captures_survive_allocations_and_copies_on_other_threads() {
    let rounds = 30;
    std::thread::scope(|scope| {
        let capturer = scope.spawn(|| {
            let k = setup();
            let s = k.gpu.stream();
            let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
            let cond = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
            for round in 0..rounds {
                let graph = s
                    .capture(|s| {
                        for _ in 0..50 {
                            k.add(s, &counter, 1)?;
                        }
                        s.capture_while(&whole(&cond), |s| k.decrement(s, &cond))
                    })
                    .unwrap_or_else(|e| panic!("capture in round {round}: {e}"));
                write_i32(&cond, 3);
                graph.launch(s).unwrap();
                s.synchronize().unwrap();
            }
            read_u32(&counter)
        });
        let churner = scope.spawn(|| {
            let gpu = Gpu::open(0).unwrap();
            let mut moved = 0usize;
            for i in 0..rounds * 10 {
                let memory = gpu.alloc_zeroed(1 << 16).map(Arc::new).unwrap();
                memory.copy_from_host(0, &[i as u8; 256]).unwrap();
                let mut back = [0u8; 256];
                memory.copy_to_host(0, &mut back).unwrap();
                assert_eq!(back, [i as u8; 256]);
                moved += back.len();
                if i % 50 == 0 {
                    drop(gpu.load_ptx("churn", KERNELS_PTX.as_bytes()).unwrap());
                }
            }
            moved
        });
        assert_eq!(capturer.join().unwrap(), 50 * rounds);
        println!(
            "{rounds} captures with a WHILE node while another thread allocated, copied {} bytes, freed and loaded modules",
            churner.join().unwrap()
        );
    });
}

#[test]
fn graph_replay_of_many_kernels_is_fast() {
    let k = setup();
    let s = k.gpu.stream();
    let counter = k.gpu.alloc_zeroed(4).map(Arc::new).unwrap();
    let nodes = 1000;
    let graph = s
        .capture(|s| {
            for _ in 0..nodes {
                k.add(s, &counter, 1)?;
            }
            Ok::<(), CudaError>(())
        })
        .unwrap();
    graph.upload(s).unwrap();
    graph.launch(s).unwrap();
    s.synchronize().unwrap();
    let start = k.gpu.new_event().unwrap();
    let end = k.gpu.new_event().unwrap();
    start.record(s).unwrap();
    for _ in 0..10 {
        graph.launch(s).unwrap();
    }
    end.record(s).unwrap();
    let ms = start.elapsed_ms(&end).unwrap();
    assert_eq!(read_u32(&counter), 11 * nodes);
    println!(
        "{nodes}-kernel graph: {:.2} us per node on the GPU",
        ms as f64 * 1000.0 / (10.0 * nodes as f64)
    );
}

#[test]
fn nvtx_ranges_never_panic() {
    let outer = NvtxRange::push("instantmimic test");
    let inner = NvtxRange::push("with a \0 NUL");
    drop(inner);
    drop(outer);
    println!("NVTX push/pop ran (a no-op when libnvToolsExt is absent)");
}

#[test]
fn readback_returns_the_bytes_of_the_last_queued_copy_only_once_it_is_done() {
    let gpu = Gpu::open(0).unwrap();
    let memory = gpu.alloc_zeroed(4096).map(Arc::new).unwrap();
    let mut readback = instantmimic::cuda::Readback::new(&gpu, 1024).unwrap();
    assert!(readback.wait().unwrap().is_none(), "nothing queued yet");
    let stream = gpu.stream();
    for round in 0u8..3 {
        let bytes: Vec<u8> = (0..1024u32)
            .map(|i| (i as u8).wrapping_mul(7) ^ round)
            .collect();
        memory.copy_from_host(512, &bytes).unwrap();
        readback
            .queue(stream, &range(&memory, 512, bytes.len()).unwrap())
            .unwrap();
        assert_eq!(
            readback.wait().unwrap().unwrap(),
            &bytes[..],
            "round {round}"
        );
    }
    readback
        .queue(stream, &range(&memory, 0, 16).unwrap())
        .unwrap();
    assert_eq!(readback.wait().unwrap().unwrap(), &[0u8; 16][..]);
    let too_big = readback
        .queue(stream, &range(&memory, 0, 1025).unwrap())
        .unwrap_err();
    assert!(too_big.to_string().contains("Readback::queue"), "{too_big}");
}
