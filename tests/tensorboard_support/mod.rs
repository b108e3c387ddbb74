//! TensorBoard's own reader (its `EventAccumulator`, in the build-step Python named by
//! `INSTANTMIMIC_BUILD_PYTHON`) on a run directory: every scalar tag's (step, value) pairs.

use std::collections::BTreeMap;
use std::path::Path;

use super::skip_support;

const READ: &str = r#"
import json, sys
try:
    from tensorboard.backend.event_processing import event_accumulator
except ImportError as e:
    print("no tensorboard: " + str(e))
    sys.exit(3)
acc = event_accumulator.EventAccumulator(sys.argv[1], size_guidance={event_accumulator.SCALARS: 0})
acc.Reload()
tags = acc.Tags()["scalars"]
print(json.dumps({t: [[e.step, e.value] for e in acc.Scalars(t)] for t in tags}))
"#;

/// Every scalar tag of the event files under `dir` as TensorBoard reads them; `None` after a
/// skip note when the build-step Python or its `tensorboard` is missing.
pub fn tensorboard_scalars(dir: &Path) -> Option<BTreeMap<String, Vec<(i64, f64)>>> {
    let Some(python) = std::env::var_os("INSTANTMIMIC_BUILD_PYTHON") else {
        skip_support::skip("INSTANTMIMIC_BUILD_PYTHON is not set (tests/run.sh sets it)");
        return None;
    };
    let out = std::process::Command::new(&python)
        .args(["-c", READ])
        .arg(dir)
        .output()
        .expect("the build-step Python runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    if out.status.code() == Some(3) {
        skip_support::skip(&format!(
            "{} (kernels_py/requirements.txt has it; tests/run.sh installs it)",
            stdout.trim()
        ));
        return None;
    }
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_str(stdout.trim()).expect("the reader's JSON"))
}
