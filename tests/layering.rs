//! The lower floors import only what lies below them (docs/architecture.md): every `crate::X`
//! a file of `src/<floor>/` (or `src/<floor>.rs`) names outside comments must be one of the
//! floor's allowed modules. The floors above `env` and `nn` (train, ppo, latent and their
//! neighbours) still have cycles the `train/` split removes; they join this list then.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Each lower floor and the modules it may import, bottom up.
const FLOORS: &[(&str, &[&str])] = &[
    ("cuda", &[]),
    ("files", &[]),
    ("assets", &[]),
    ("motion", &["files"]),
    ("plan", &["assets", "cuda", "files"]),
    ("kernels", &["assets", "cuda", "plan", "files"]),
    ("nn", &["cuda", "kernels"]),
    ("recording", &["files", "motion"]),
    (
        "env",
        &["assets", "cuda", "files", "kernels", "motion", "plan"],
    ),
];

fn rust_files(floor: &str) -> Vec<PathBuf> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    let single = src.join(format!("{floor}.rs"));
    if single.is_file() {
        files.push(single);
    }
    let mut dirs = vec![src.join(floor)];
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }
    files
}

/// The modules `text` names as `crate::X`, comments left out.
fn crate_modules(text: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or("");
        let mut rest = code;
        while let Some(at) = rest.find("crate::") {
            rest = &rest[at + "crate::".len()..];
            let name: String = rest
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                found.insert(name);
            }
        }
    }
    found
}

#[test]
fn the_lower_floors_import_only_downward() {
    let mut violations = Vec::new();
    for (floor, allowed) in FLOORS {
        let files = rust_files(floor);
        assert!(!files.is_empty(), "src/{floor}: no Rust file found");
        for file in files {
            let text = std::fs::read_to_string(&file).expect("a source file");
            for module in crate_modules(&text) {
                if module != *floor && !allowed.contains(&module.as_str()) {
                    violations.push(format!(
                        "{}: imports crate::{module}, which is not below {floor}",
                        file.display()
                    ));
                }
            }
        }
    }
    assert!(violations.is_empty(), "{}", violations.join("\n"));
}

#[test]
fn the_import_scan_sees_code_and_skips_comments() {
    let found = crate_modules("use crate::cuda::Gpu; // crate::train\nlet x = crate::plan::X;");
    assert_eq!(
        found.into_iter().collect::<Vec<_>>(),
        ["cuda".to_string(), "plan".to_string()]
    );
}
