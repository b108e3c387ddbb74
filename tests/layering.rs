//! The layers of `src/` (docs/architecture.md), checked from the code: every `crate::X` a file
//! of `src/<floor>/` (or `src/<floor>.rs`) names outside comments must be one of the floor's
//! allowed modules, and the files of the task, learner and run folders import each other
//! without a loop.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The modules below the learners: every floor under `train` may import these.
const BELOW_TRAIN: &[&str] = &[
    "assets",
    "cuda",
    "env",
    "files",
    "kernels",
    "latent",
    "motion",
    "nn",
    "plan",
    "plot",
    "ppo",
    "recording",
    "run",
    "world",
];

/// Each floor and the modules it may import, bottom up (docs/architecture.md).
const FLOORS: &[(&str, &[&str])] = &[
    ("cuda", &[]),
    ("files", &[]),
    ("assets", &[]),
    ("plot", &[]),
    // One run across processes: std's TCP, nothing of CUDA or training.
    ("world", &[]),
    ("motion", &["files"]),
    ("plan", &["assets", "cuda", "files"]),
    ("kernels", &["assets", "cuda", "plan", "files"]),
    ("nn", &["cuda", "kernels"]),
    ("recording", &["files", "motion"]),
    (
        "env",
        &["assets", "cuda", "files", "kernels", "motion", "plan"],
    ),
    // The run harness knows no learner and no training configuration.
    ("run", &["env", "files", "motion", "plan", "plot"]),
    // The learners, each beside its algorithm, on the run harness's seam (`run::Learner`). A
    // latent goal run's PPO head drives the latent controller's frozen decoder, so `ppo` sits
    // over `latent`.
    ("latent", &["cuda", "env", "kernels", "nn", "plan", "run"]),
    (
        "ppo",
        &[
            "cuda", "env", "kernels", "latent", "nn", "plan", "run", "world",
        ],
    ),
    ("train", BELOW_TRAIN),
    ("viewer", &["files", "motion", "recording"]),
];

/// The tools over `train`: each may import `train` and everything below it, `viewer`, and no
/// other tool.
const TOOLS: &[&str] = &["replay", "export", "bench", "hpo"];

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
fn every_floor_imports_only_downward() {
    let mut allowed_of: Vec<(&str, Vec<&str>)> = FLOORS
        .iter()
        .map(|(floor, allowed)| (*floor, allowed.to_vec()))
        .collect();
    for tool in TOOLS {
        let mut allowed = BELOW_TRAIN.to_vec();
        allowed.extend(["train", "viewer"]);
        allowed_of.push((tool, allowed));
    }
    let mut violations = Vec::new();
    for (floor, allowed) in &allowed_of {
        let files = rust_files(floor);
        assert!(!files.is_empty(), "src/{floor}: no Rust file found");
        for file in files {
            let text = std::fs::read_to_string(&file).expect("a source file");
            for module in crate_modules(&text) {
                if module != *floor && !allowed.contains(&module.as_str()) {
                    violations.push(format!(
                        "{}: imports crate::{module}, which is not below {floor}",
                        shown(&file)
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

/// Folders whose files import each other without a loop: the tasks, the NN toolkit, the run
/// harness, the learners and the training configuration.
const ACYCLIC_FOLDERS: &[&str] = &["env", "nn", "run", "ppo", "latent", "train"];

/// The module path of a file under `src/` (`src/env/rollout/mod.rs` -> `env::rollout`).
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(src).expect("a file under src/");
    let mut parts: Vec<String> = relative
        .with_extension("")
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    parts
}

/// Every path expression `crate::a::b`, `super::a`, `self::a` of `text` (comments left out),
/// with a brace group's members as paths of their own: `use super::{a::X, b}` gives `super::a`
/// and `super::b`.
fn path_expressions(text: &str) -> Vec<Vec<String>> {
    // Comments out, lines joined: a `use` group may span lines.
    let code: Vec<char> = text
        .lines()
        .map(|line| line.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
        .chars()
        .collect();
    let is_name = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let at = |i: usize, pattern: &str| {
        pattern
            .chars()
            .enumerate()
            .all(|(k, p)| code.get(i + k) == Some(&p))
    };
    let name_at = |i: usize| -> String { code[i..].iter().take_while(|c| is_name(**c)).collect() };
    let mut paths = Vec::new();
    let mut i = 0;
    while i < code.len() {
        let starts = (i == 0 || !is_name(code[i - 1]))
            && ["crate::", "super::", "self::"].iter().any(|p| at(i, p));
        if !starts {
            i += 1;
            continue;
        }
        let mut segments = Vec::new();
        let mut j = i;
        loop {
            let name = name_at(j);
            if name.is_empty() {
                break;
            }
            j += name.len();
            segments.push(name);
            if at(j, "::") {
                j += 2;
            } else {
                break;
            }
        }
        if code.get(j) == Some(&'{') {
            let close = code[j..]
                .iter()
                .position(|c| *c == '}')
                .map_or(code.len(), |k| j + k);
            let group: String = code[j + 1..close].iter().collect();
            for member in group.split(',') {
                let first: String = member.trim().chars().take_while(|c| is_name(*c)).collect();
                if !first.is_empty() {
                    let mut path = segments.clone();
                    path.push(first);
                    paths.push(path);
                }
            }
            j = close;
        } else if !segments.is_empty() {
            paths.push(segments);
        }
        i = j.max(i + 1);
    }
    paths
}

/// The file-level import graph of `folders` (edges only between their files): a path to a
/// module resolves to its file; a name a `mod.rs` re-exports (`pub use a::{X, Y}`) resolves to
/// the file that defines it.
fn import_graph(folders: &[&str]) -> Vec<(PathBuf, Vec<PathBuf>)> {
    use std::collections::BTreeMap;
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files: Vec<PathBuf> = folders.iter().flat_map(|f| rust_files(f)).collect();
    let texts: Vec<String> = files
        .iter()
        .map(|f| std::fs::read_to_string(f).expect("a source file"))
        .collect();
    let modules: BTreeMap<Vec<String>, PathBuf> = files
        .iter()
        .map(|f| (module_path(&src, f), f.clone()))
        .collect();
    let mut reexports: BTreeMap<Vec<String>, Vec<String>> = BTreeMap::new();
    for (file, text) in files.iter().zip(&texts) {
        if file.file_name().is_some_and(|n| n == "mod.rs") {
            let base = module_path(&src, file);
            for path in path_expressions(&text.replace("pub use ", "pub use self::")) {
                if path.len() == 3 && path[0] == "self" {
                    let mut name = base.clone();
                    name.push(path[2].clone());
                    let mut module = base.clone();
                    module.push(path[1].clone());
                    reexports.insert(name, module);
                }
            }
        }
    }
    let mut graph = Vec::new();
    for (file, text) in files.iter().zip(&texts) {
        let me = module_path(&src, file);
        let mut targets = BTreeSet::new();
        for path in path_expressions(text) {
            let mut at = me.clone();
            let mut rest = path.as_slice();
            match rest.first().map(String::as_str) {
                Some("crate") => {
                    at.clear();
                    rest = &rest[1..];
                }
                Some("self") => rest = &rest[1..],
                _ => {
                    while rest.first().is_some_and(|s| s == "super") {
                        at.pop();
                        rest = &rest[1..];
                    }
                }
            }
            let full: Vec<String> = at.iter().chain(rest).cloned().collect();
            let Some(k) = (1..=full.len())
                .rev()
                .find(|&k| modules.contains_key(&full[..k]))
            else {
                continue;
            };
            let mut target = modules[&full[..k]].clone();
            if let Some(next) = full.get(k) {
                let mut name = full[..k].to_vec();
                name.push(next.clone());
                if let Some(defined) = reexports.get(&name).and_then(|m| modules.get(m)) {
                    target = defined.clone();
                }
            }
            if target != *file {
                targets.insert(target);
            }
        }
        graph.push((file.clone(), targets.into_iter().collect()));
    }
    graph
}

/// The loops of `graph` (its strongly connected components of more than one file).
fn import_cycles(graph: &[(PathBuf, Vec<PathBuf>)]) -> Vec<Vec<PathBuf>> {
    let index_of = |p: &PathBuf| graph.iter().position(|(f, _)| f == p);
    let edges: Vec<Vec<usize>> = graph
        .iter()
        .map(|(_, ts)| ts.iter().filter_map(index_of).collect())
        .collect();
    // Kosaraju: finish order on the graph, then components on the reversed graph.
    let n = edges.len();
    let mut order = Vec::new();
    let mut seen = vec![false; n];
    for start in 0..n {
        let mut stack = vec![(start, 0usize)];
        if seen[start] {
            continue;
        }
        seen[start] = true;
        while let Some((v, next)) = stack.pop() {
            if let Some(&w) = edges[v].get(next) {
                stack.push((v, next + 1));
                if !seen[w] {
                    seen[w] = true;
                    stack.push((w, 0));
                }
            } else {
                order.push(v);
            }
        }
    }
    let mut reversed = vec![Vec::new(); n];
    for (v, ws) in edges.iter().enumerate() {
        for &w in ws {
            reversed[w].push(v);
        }
    }
    let mut component = vec![usize::MAX; n];
    let mut cycles = Vec::new();
    for &root in order.iter().rev() {
        if component[root] != usize::MAX {
            continue;
        }
        let mut members = vec![root];
        component[root] = root;
        let mut stack = vec![root];
        while let Some(v) = stack.pop() {
            for &w in &reversed[v] {
                if component[w] == usize::MAX {
                    component[w] = root;
                    members.push(w);
                    stack.push(w);
                }
            }
        }
        if members.len() > 1 {
            let mut files: Vec<PathBuf> = members.iter().map(|&i| graph[i].0.clone()).collect();
            files.sort();
            cycles.push(files);
        }
    }
    cycles
}

/// `path` from the repository's root.
fn shown(path: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    path.strip_prefix(root)
        .unwrap_or(path)
        .display()
        .to_string()
}

#[test]
fn the_task_and_learner_folders_have_no_file_level_import_cycle() {
    let graph = import_graph(ACYCLIC_FOLDERS);
    let cycles = import_cycles(&graph);
    let described: Vec<String> = cycles
        .iter()
        .map(|files| {
            files
                .iter()
                .map(|f| {
                    let (_, targets) = graph.iter().find(|(g, _)| g == f).expect("a file");
                    let inside: Vec<String> = targets
                        .iter()
                        .filter(|t| files.contains(t))
                        .map(|t| shown(t))
                        .collect();
                    format!("  {} imports {}", shown(f), inside.join(", "))
                })
                .collect::<Vec<_>>()
                .join("\n")
        })
        .collect();
    assert!(
        cycles.is_empty(),
        "files that import each other in a loop (move the shared item below them):\n{}",
        described.join("\n\n")
    );
}

/// The graph and the cycle search see a loop through a brace group and a `mod.rs` re-export,
/// and none in a chain.
#[test]
fn the_cycle_search_finds_a_loop_and_passes_a_chain() {
    let paths = path_expressions("use super::{a::X, b};\nlet y = crate::c::d::Y; // super::e");
    assert_eq!(
        paths,
        [
            vec!["super".to_string(), "a".into()],
            vec!["super".into(), "b".into()],
            vec!["crate".into(), "c".into(), "d".into(), "Y".into()],
        ]
    );
    let multi_line = path_expressions("use super::{\n    a::X, // super::z\n    b,\n};");
    assert_eq!(
        multi_line,
        [
            vec!["super".to_string(), "a".into()],
            vec!["super".into(), "b".into()]
        ]
    );
    let file = |n: &str| PathBuf::from(n);
    let looped = [
        (file("a"), vec![file("b")]),
        (file("b"), vec![file("c")]),
        (file("c"), vec![file("a")]),
        (file("d"), vec![file("a")]),
    ];
    assert_eq!(
        import_cycles(&looped),
        [vec![file("a"), file("b"), file("c")]]
    );
    let chain = [
        (file("a"), vec![file("b")]),
        (file("b"), vec![]),
        (file("c"), vec![file("a")]),
    ];
    assert!(import_cycles(&chain).is_empty());
}
