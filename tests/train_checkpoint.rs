//! Checkpoints: round trip, every corruption case, atomic replacement, keeping the last K and
//! finding the newest good one.

use std::path::Path;

use instantmimic::run::{
    CHECKPOINT_FORMAT_VERSION, Checkpoint, CheckpointDir, CheckpointError, CheckpointMeta,
    TensorData,
};
use instantmimic::train::{TrainConfig, write_atomically};

fn config() -> TrainConfig {
    let mut c = TrainConfig::with_motion("backflip");
    c.seed = 3;
    c.ppo.learning_rate = 6.25e-4;
    c.run.eval_steps = Some(60);
    c
}

fn checkpoint(iteration: u64) -> Checkpoint {
    let meta = CheckpointMeta::new(
        &config(),
        iteration,
        0.125 * iteration as f64,
        131_072 * iteration,
    )
    .unwrap();
    let mut c = Checkpoint::new(meta);
    let actor: Vec<f32> = (0..12)
        .map(|i| i as f32 * 0.5 - 1.0 + iteration as f32)
        .collect();
    c.insert("actor.params", &[3, 4], actor).unwrap();
    c.insert(
        "obs_norm.mean",
        &[5],
        vec![1e-300, -2.5, f64::MAX, 0.1, 1.0 / 3.0],
    )
    .unwrap();
    c.insert("counters", &[2], vec![iteration as i32, -7])
        .unwrap();
    c.insert("adam.step", &[], vec![iteration as f64]).unwrap();
    c
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn round_trip_keeps_every_value_shape_and_the_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.safetensors");
    let original = checkpoint(40);
    original.save(&path).unwrap();
    let back = Checkpoint::load(&path).unwrap();
    assert_eq!(back.meta, original.meta);
    assert_eq!(back.meta.format_version, CHECKPOINT_FORMAT_VERSION);
    assert_eq!(back.meta.crate_version, env!("CARGO_PKG_VERSION"));
    assert_eq!(
        back.meta.config::<TrainConfig>(back.source()).unwrap(),
        config()
    );
    for name in ["actor.params", "obs_norm.mean", "counters", "adam.step"] {
        assert_eq!(back.tensor(name), original.tensor(name), "{name}");
    }
    assert_eq!(
        back.get::<f32>("actor.params", &[3, 4]).unwrap()[11],
        4.5 + 40.0
    );
    assert_eq!(back.get::<f64>("adam.step", &[]).unwrap(), [40.0]);
    assert_eq!(back.get::<i32>("counters", &[2]).unwrap(), [40, -7]);
    // The file is plain safetensors: the crate's own reader sees dtype and shape.
    let bytes = std::fs::read(&path).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let view = st.tensor("obs_norm.mean").unwrap();
    assert_eq!(view.dtype(), safetensors::Dtype::F64);
    assert_eq!(view.shape(), [5]);
}

#[test]
fn the_caller_is_told_about_missing_tensors_and_wrong_shapes_or_types() {
    let c = checkpoint(1);
    let e = c
        .get::<f32>("critic.params", &[10])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no tensor `critic.params`") && e.contains("actor.params, adam.step"),
        "{e}"
    );
    let e = c.get::<f32>("actor.params", &[12]).unwrap_err().to_string();
    assert!(
        e.contains("`actor.params` is f32 [3, 4], expected f32 [12]"),
        "{e}"
    );
    let e = c
        .get::<f64>("actor.params", &[3, 4])
        .unwrap_err()
        .to_string();
    assert!(e.contains("is f32 [3, 4], expected f64 [3, 4]"), "{e}");
    let mut c = c;
    let e = c.insert("x", &[2, 3], vec![1.0f32; 5]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "tensor `x`: shape [2, 3] holds 6 values, got 5"
    );
    assert_eq!(TensorData::from(vec![1i32, 2]).len(), 2);
}

#[test]
fn every_corruption_is_reported_with_the_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let good = checkpoint(5).to_bytes().unwrap();
    let path = dir.path().join("bad.safetensors");
    let load_err = |bytes: &[u8]| {
        write(&path, bytes);
        let e = Checkpoint::load(&path).unwrap_err();
        assert!(matches!(e, CheckpointError::Corrupt { .. }), "{e:?}");
        let text = e.to_string();
        assert!(text.starts_with(&path.display().to_string()), "{text}");
        text
    };
    // Truncated anywhere: in the length, the header, the data, or by one byte.
    for cut in [0, 4, 8, 20, good.len() / 2, good.len() - 1] {
        let e = load_err(&good[..cut]);
        assert!(e.contains("corrupt or truncated"), "cut {cut}: {e}");
    }
    // Trailing garbage.
    let mut longer = good.clone();
    longer.extend_from_slice(b"xx");
    let e = load_err(&longer);
    assert!(e.contains("shorter or longer than its header says"), "{e}");
    // One flipped bit in the tensor data: the checksum catches it.
    let mut flipped = good.clone();
    let last = flipped.len() - 3;
    flipped[last] ^= 0x10;
    let e = load_err(&flipped);
    assert!(e.contains("does not match its checksum"), "{e}");
    // A flipped byte in the JSON header.
    let mut header = good.clone();
    header[9] = b'#';
    let e = load_err(&header);
    assert!(e.contains("invalid JSON"), "{e}");
    // Not a safetensors file at all.
    let e = load_err(b"this is not a checkpoint at all, just text");
    assert!(e.contains("corrupt or truncated"), "{e}");
    // A safetensors file written by someone else.
    let foreign = safetensors::serialize(
        [(
            "w",
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![1], &[0, 0, 0, 0])
                .unwrap(),
        )],
        None,
    )
    .unwrap();
    let e = load_err(&foreign);
    assert!(e.contains("not an instantmimic checkpoint"), "{e}");
    // An unreadable file names the path.
    let missing = dir.path().join("missing.safetensors");
    let e = Checkpoint::load(&missing).unwrap_err().to_string();
    assert!(e.starts_with(&missing.display().to_string()), "{e}");
}

#[test]
fn a_newer_format_is_refused_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("new.safetensors");
    let mut c = checkpoint(1);
    c.meta.format_version = CHECKPOINT_FORMAT_VERSION + 1;
    c.save(&path).unwrap();
    let e = Checkpoint::load(&path).unwrap_err();
    assert!(matches!(e, CheckpointError::NewerFormat { .. }), "{e}");
    assert!(e.to_string().contains("use a newer instantmimic"), "{e}");
}

#[test]
fn a_crash_mid_write_leaves_the_previous_checkpoint_readable() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("latest.safetensors");
    checkpoint(10).save(&path).unwrap();
    // The next save dies halfway through writing its bytes.
    let next = checkpoint(20).to_bytes().unwrap();
    let result = write_atomically(&path, |file| {
        use std::io::Write;
        file.write_all(&next[..next.len() / 2])?;
        Err(std::io::Error::other("killed"))
    });
    assert!(result.is_err());
    let back = Checkpoint::load(&path).unwrap();
    assert_eq!(back.meta.iteration, 10);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
}

#[test]
fn the_directory_keeps_the_last_k_and_finds_the_newest_good_one() {
    let dir = tempfile::tempdir().unwrap();
    let checkpoints = CheckpointDir::new(&dir.path().join("checkpoints"), 3);
    assert!(checkpoints.list().unwrap().is_empty());
    assert!(checkpoints.latest_good().unwrap().latest.is_none());
    for iteration in [5, 10, 15, 20, 25] {
        checkpoints.save(&checkpoint(iteration)).unwrap();
    }
    let kept: Vec<u64> = checkpoints.list().unwrap().iter().map(|f| f.0).collect();
    assert_eq!(kept, [15, 20, 25]);
    // A process killed mid-write leaves its temporary file: ignored, then cleaned up.
    let stale = checkpoints
        .path()
        .join(".iter_00000030.safetensors.partial-999-0");
    write(&stale, b"half");
    // The newest is truncated, the next has the wrong iteration inside.
    let newest = checkpoints.file_for(25);
    let bytes = std::fs::read(&newest).unwrap();
    write(&newest, &bytes[..bytes.len() - 100]);
    std::fs::copy(checkpoints.file_for(15), checkpoints.file_for(20)).unwrap();
    let scan = checkpoints.latest_good().unwrap();
    let (path, found) = scan.latest.unwrap();
    assert_eq!((found.meta.iteration, path), (15, checkpoints.file_for(15)));
    assert_eq!(scan.skipped.len(), 2, "{:?}", scan.skipped);
    assert!(scan.skipped[0].contains("iter_00000025") && scan.skipped[0].contains("truncated"));
    assert!(scan.skipped[1].contains("holds iteration 15, not 20"));
    checkpoints.save(&checkpoint(30)).unwrap();
    assert!(!stale.exists());
}
