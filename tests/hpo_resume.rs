//! Resuming a search: N cycles then more with resume equals one run of all cycles (the
//! synthetic objective and the offline proposer are deterministic), after a clean stop, after
//! a half-written cycle, and after a kill of the running command.

mod hpo_support;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use hpo_support::{binary, config_text, offline_config, read};
use instantmimic::hpo::backend::offline::OfflineProposer;
use instantmimic::hpo::trial::build_runners;
use instantmimic::hpo::{HpoConfig, RunnerPool, Search};

/// The files that must match between a resumed run and a straight one.
const STATE_FILES: [&str; 5] = [
    "history.jsonl",
    "state.json",
    "strategy.md",
    "incumbent.toml",
    "best.toml",
];

fn run_to(search: &mut Search, last_cycle: u32) {
    let config = search.config().clone();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    search
        .run(
            &mut OfflineProposer,
            &mut pool,
            last_cycle,
            &mut std::io::sink(),
        )
        .unwrap();
}

fn straight_run(config: &HpoConfig, dir: &Path, last_cycle: u32) {
    let mut search = Search::new(config.clone(), dir).unwrap();
    run_to(&mut search, last_cycle);
}

fn assert_same_state(a: &Path, b: &Path) {
    for file in STATE_FILES {
        let (left, right) = (read(&a.join(file)), read(&b.join(file)));
        // Report the first differing line, shortened: whole files are too long to read.
        if let Some((i, (l, r))) = left
            .lines()
            .zip(right.lines())
            .enumerate()
            .find(|(_, (l, r))| l != r)
        {
            let at = l.bytes().zip(r.bytes()).take_while(|(x, y)| x == y).count();
            let cut = |s: &str| {
                s.get(at.saturating_sub(80)..(at + 80).min(s.len()))
                    .unwrap_or_default()
                    .to_string()
            };
            panic!(
                "{file} line {} differs near byte {at}:\n{}\n{}",
                i + 1,
                cut(l),
                cut(r)
            );
        }
        assert_eq!(
            left.lines().count(),
            right.lines().count(),
            "{file}: line counts differ"
        );
    }
}

#[test]
fn resuming_after_n_cycles_equals_one_run() {
    let config = offline_config("", "");
    let tmp = tempfile::tempdir().unwrap();
    let (straight, resumed) = (tmp.path().join("straight"), tmp.path().join("resumed"));
    straight_run(&config, &straight, 7);

    let mut first = Search::new(config.clone(), &resumed).unwrap();
    run_to(&mut first, 3);
    drop(first);
    let mut second = Search::resume(&resumed, None).unwrap();
    assert_eq!(second.cycles_done(), 3);
    run_to(&mut second, 7);
    assert_same_state(&straight, &resumed);
    assert_eq!(read(&straight.join("history.jsonl")).lines().count(), 8);
}

#[test]
fn a_half_written_cycle_is_run_again() {
    let config = offline_config("", "");
    let tmp = tempfile::tempdir().unwrap();
    let (straight, resumed) = (tmp.path().join("straight"), tmp.path().join("resumed"));
    straight_run(&config, &straight, 5);

    // Run 4 cycles, then make it look as if cycle 5 died after writing its history line and
    // some exchanges, before state.json.
    let mut search = Search::new(config.clone(), &resumed).unwrap();
    run_to(&mut search, 4);
    drop(search);
    let history = read(&straight.join("history.jsonl"));
    std::fs::write(resumed.join("history.jsonl"), &history).unwrap();
    let stale = resumed.join("exchanges/cycle_005");
    std::fs::create_dir_all(&stale).unwrap();
    std::fs::write(stale.join("propose_9.prompt.md"), "left by the killed run").unwrap();
    std::fs::write(resumed.join("state.json.tmp"), "{ half").unwrap();

    let mut search = Search::resume(&resumed, None).unwrap();
    assert_eq!(search.cycles_done(), 4, "cycle 5 was not committed");
    run_to(&mut search, 5);
    assert_same_state(&straight, &resumed);
    assert!(
        !stale.join("propose_9.prompt.md").exists(),
        "stale exchanges are cleared"
    );
}

#[test]
fn resume_refuses_a_different_search_and_a_non_run_directory() {
    let config = offline_config("", "");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    straight_run(&config, &dir, 1);
    let mut other = config.clone();
    other.search.seeds = vec![0, 1];
    let err = Search::resume(&dir, Some(other)).err().unwrap().to_string();
    assert!(err.contains("the seeds differs"), "{err}");
    // The same search with another agent setting is fine.
    let mut same = config.clone();
    same.search.propose_attempts = 5;
    assert!(Search::resume(&dir, Some(same)).is_ok());
    let err = Search::resume(tmp.path(), None).err().unwrap().to_string();
    assert!(err.contains("not a search's run directory"), "{err}");
    let err = Search::new(config, &dir).err().unwrap().to_string();
    assert!(err.contains("--resume"), "{err}");
}

#[test]
fn a_killed_command_resumes_where_it_stopped() {
    let tmp = tempfile::tempdir().unwrap();
    let config_path = tmp.path().join("hpo.toml");
    // Trials take 15 ms, so 8 cycles of 9-12 trials take over a second: the kill lands
    // mid-search.
    let text = config_text("[agent]\nbackend = \"offline\"\n", "", "")
        .replace("noise = 0.05", "noise = 0.05\ntrial_delay_ms = 15");
    std::fs::write(&config_path, &text).unwrap();
    let killed = tmp.path().join("killed");
    let mut child = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config_path)
        .args(["--cycles", "8", "--out"])
        .arg(&killed)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Wait for cycle 2 to be committed, then kill.
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let done = std::fs::read_to_string(killed.join("history.jsonl"))
            .map(|h| h.lines().count())
            .unwrap_or(0);
        if done >= 3 || Instant::now() > deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let history = read(&killed.join("history.jsonl"));
    assert!(history.lines().count() < 9, "the kill came before the end");

    let output = Command::new(binary())
        .args(["hpo", "--resume"])
        .arg(&killed)
        .args(["--cycles", "8"])
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );

    let config = HpoConfig::parse(&text, "test", tmp.path(), "test").unwrap();
    let straight = tmp.path().join("straight");
    straight_run(&config, &straight, 8);
    assert_same_state(&straight, &killed);
    assert!(killed.join("trajectory.png").exists() && killed.join("summary.md").exists());
}

/// A time limit stops the search between cycles (here at once: the limit has passed when the
/// baseline ends), and resuming without one gives the state of a straight run.
#[test]
fn a_time_limit_stops_between_cycles_and_resume_finishes_the_same_search() {
    let config = offline_config("", "");
    let (straight, limited) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    straight_run(&config, straight.path(), 3);
    let mut search = Search::new(config.clone(), limited.path()).unwrap();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    let mut progress = Vec::new();
    let complete = search
        .run_until(
            &mut OfflineProposer,
            &mut pool,
            3,
            Some(Instant::now()),
            &mut progress,
        )
        .unwrap();
    assert!(!complete);
    assert_eq!(search.cycles_done(), 0, "only the baseline ran");
    let progress = String::from_utf8(progress).unwrap();
    assert!(
        progress.contains("stopping before cycle 1") && progress.contains("--resume"),
        "{progress}"
    );
    // A limit far away does not stop it.
    let complete = search
        .run_until(
            &mut OfflineProposer,
            &mut pool,
            1,
            Some(Instant::now() + Duration::from_secs(3600)),
            &mut std::io::sink(),
        )
        .unwrap();
    assert!(complete);
    let mut resumed = Search::resume(limited.path(), None).unwrap();
    run_to(&mut resumed, 3);
    assert_same_state(straight.path(), limited.path());
}
