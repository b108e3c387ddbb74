//! The helper processes' side of compiling PTX at once (src/cuda/jit_cache.rs), on the CPU: the
//! modules as a helper reads them, and their spread over the helpers.

use instantmimic::cuda::jit_cache::{read_modules, spread_by_size, write_modules};

#[test]
fn modules_read_back_as_written() {
    let big = vec![7u8; 100_000];
    let modules: Vec<(&str, &[u8])> = vec![("a.ptx", b".version 8.0"), ("", b""), ("big", &big)];
    let mut bytes = Vec::new();
    write_modules(&mut bytes, &modules).unwrap();
    let read = read_modules(&mut bytes.as_slice()).unwrap();
    assert_eq!(read.len(), 3);
    for ((name, ptx), (read_name, read_ptx)) in modules.iter().zip(&read) {
        assert_eq!(name, read_name);
        assert_eq!(ptx, &read_ptx.as_slice());
    }
    assert!(read_modules(&mut [].as_slice()).unwrap().is_empty());
}

#[test]
fn a_cut_stream_is_an_error() {
    let mut bytes = Vec::new();
    write_modules(&mut bytes, &[("m", b"0123456789")]).unwrap();
    for cut in [2, 5, bytes.len() - 1] {
        assert!(
            read_modules(&mut &bytes[..cut]).is_err(),
            "a stream cut at {cut} of {} bytes read as whole",
            bytes.len()
        );
    }
}

#[test]
fn modules_spread_over_sets_of_about_equal_size() {
    let sizes = [1100, 760, 470, 390, 180, 180, 150, 120, 100, 90];
    let sets = spread_by_size(&sizes, 4);
    assert_eq!(sets.len(), 4);
    let mut all: Vec<usize> = sets.iter().flatten().copied().collect();
    all.sort_unstable();
    assert_eq!(
        all,
        (0..sizes.len()).collect::<Vec<_>>(),
        "every module once"
    );
    let totals: Vec<usize> = sets
        .iter()
        .map(|s| s.iter().map(|&i| sizes[i]).sum())
        .collect();
    // The largest module alone bounds the heaviest set.
    assert_eq!(*totals.iter().max().unwrap(), 1100, "{totals:?}");
    // More sets than modules: one module per set, no empty set.
    assert_eq!(spread_by_size(&[5, 3], 8).len(), 2);
    assert!(spread_by_size(&[], 3).is_empty());
}
