//! Stopping a search on SIGINT/SIGTERM: the runner pool starts no trial once a stop is
//! requested, the search ends with `HpoError::Interrupted` at its last committed cycle, and
//! `hpo --resume` then gives the state of a straight run. The command itself, sent SIGTERM
//! (or SIGINT) while it runs the synthetic objective, says how to resume and exits with 143
//! (130); a second SIGINT ends it at once, its state still resumable, and a second SIGTERM (as
//! `timeout` may send) stops it cleanly as one does.

mod hpo_support;

use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use hpo_support::{binary, config_text, offline_config, read};
use instantmimic::hpo::backend::offline::OfflineProposer;
use instantmimic::hpo::experiment::{Candidate, run_experiment};
use instantmimic::hpo::trial::{BoxedRunner, build_runners};
use instantmimic::hpo::{HpoConfig, HpoError, RunnerPool, Search, TrialOutcome, TrialRunner};
use instantmimic::run::{StopFlag, StopSignal};

/// The synthetic runner, with a stop requested (as a signal would) during trial `stop_in`
/// (counted from 1 across the runner's life); that trial still completes.
struct StopDuring {
    inner: BoxedRunner,
    trials: Arc<AtomicUsize>,
    stop_in: usize,
    flag: Option<StopFlag>,
}

impl TrialRunner for StopDuring {
    fn run(&mut self, config: &toml::Table, seed: u64) -> Result<TrialOutcome, HpoError> {
        let n = self.trials.fetch_add(1, Ordering::SeqCst) + 1;
        if n == self.stop_in {
            let flag = self
                .flag
                .as_ref()
                .expect("the pool gave the runner its flag");
            flag.request(StopSignal::Terminate);
        }
        self.inner.run(config, seed)
    }

    fn stop_on(&mut self, stop: &StopFlag) {
        self.flag = Some(stop.clone());
    }
}

fn stopping_pool(config: &HpoConfig, stop_in: usize) -> (RunnerPool, Arc<AtomicUsize>) {
    let trials = Arc::new(AtomicUsize::new(0));
    let inner = build_runners(&config.runner, config.objective)
        .unwrap()
        .pop()
        .unwrap();
    let runner = StopDuring {
        inner,
        trials: Arc::clone(&trials),
        stop_in,
        flag: None,
    };
    let mut pool = RunnerPool::new(vec![Box::new(runner) as BoxedRunner]).unwrap();
    pool.stop_on(StopFlag::new());
    (pool, trials)
}

#[test]
fn no_trial_starts_after_a_stop_request() {
    let config = offline_config("", "");
    let (mut pool, trials) = stopping_pool(&config, 2);
    let candidates = [Candidate {
        value: None,
        assignment: config.baseline().unwrap(),
    }];
    let result = run_experiment(&mut pool, &config.base, &candidates, &[0, 1, 2, 3], 20.0);
    assert!(
        matches!(
            result,
            Err(HpoError::Interrupted {
                signal: StopSignal::Terminate
            })
        ),
        "{result:?}"
    );
    // The trial the request came in finished; the 3rd and 4th never started.
    assert_eq!(trials.load(Ordering::SeqCst), 2);
    assert_eq!(pool.stop_requested(), Some(StopSignal::Terminate));
}

#[test]
fn an_interrupted_search_keeps_its_last_cycle_and_resumes_as_a_straight_run() {
    let config = offline_config("", "");
    let tmp = tempfile::tempdir().unwrap();
    let (stopped, straight) = (tmp.path().join("stopped"), tmp.path().join("straight"));
    // 3 seeds: the baseline is trials 1-3; the stop comes in a later cycle's experiment.
    let mut search = Search::new(config.clone(), &stopped).unwrap();
    let (mut pool, _) = stopping_pool(&config, 14);
    let result = search.run(&mut OfflineProposer, &mut pool, 4, &mut std::io::sink());
    assert!(
        matches!(result, Err(HpoError::Interrupted { .. })),
        "{result:?}"
    );
    let done = search.cycles_done();
    assert!(done < 4, "the stop came before the end: {done} cycles");
    drop(search);

    let mut resumed = Search::resume(&stopped, None).unwrap();
    assert_eq!(resumed.cycles_done(), done);
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    resumed
        .run(&mut OfflineProposer, &mut pool, 4, &mut std::io::sink())
        .unwrap();
    let mut search = Search::new(config.clone(), &straight).unwrap();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    search
        .run(&mut OfflineProposer, &mut pool, 4, &mut std::io::sink())
        .unwrap();
    for file in ["history.jsonl", "state.json", "best.toml"] {
        assert_eq!(
            read(&stopped.join(file)),
            read(&straight.join(file)),
            "{file}"
        );
    }
}

/// `hpo` on the synthetic objective with trials of `delay_ms`, up to 8 cycles, into `out`.
fn spawn_search(dir: &Path, out: &Path, delay_ms: u64) -> (Child, String) {
    let text = config_text("[agent]\nbackend = \"offline\"\n", "", "").replace(
        "noise = 0.05",
        &format!("noise = 0.05\ntrial_delay_ms = {delay_ms}"),
    );
    let config = dir.join("hpo.toml");
    std::fs::write(&config, &text).unwrap();
    let child = Command::new(binary())
        .args(["hpo", "--config"])
        .arg(&config)
        .args(["--cycles", "8", "--out"])
        .arg(out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    (child, text)
}

/// Waits until `out` holds `cycles` committed cycles (the baseline counts as one).
fn wait_for_cycles(out: &Path, cycles: usize) {
    let deadline = Instant::now() + Duration::from_secs(60);
    while Instant::now() < deadline {
        let done = std::fs::read_to_string(out.join("history.jsonl"))
            .map(|h| h.lines().count())
            .unwrap_or(0);
        if done >= cycles {
            return;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    panic!("{} cycles were not committed in 60 s", cycles);
}

fn send(child: &Child, signal: &str) {
    let status = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success(), "kill {signal}");
}

/// Sends `signal` (`kill`'s spelling) mid-search: the search stops between trials with `code`.
fn stopped_cleanly(signal: &str, name: &str, code: i32) {
    stopped_cleanly_after(&[signal], name, code);
}

/// [`stopped_cleanly`] after `signals`, sent 200 ms apart (two signals pending at once would
/// be delivered as one).
fn stopped_cleanly_after(signals: &[&str], name: &str, code: i32) {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let (child, text) = spawn_search(tmp.path(), &out, 15);
    wait_for_cycles(&out, 3);
    for (i, signal) in signals.iter().enumerate() {
        if i > 0 {
            std::thread::sleep(Duration::from_millis(200));
        }
        send(&child, signal);
    }
    let started = Instant::now();
    let output = child.wait_with_output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr),
    );
    assert_eq!(output.status.code(), Some(code), "{stdout}\n{stderr}");
    // It stopped between trials, not at the end of the search.
    assert!(started.elapsed() < Duration::from_secs(5));
    assert!(
        stdout.contains(&format!("{name} received: stopped after cycle")),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!("instantmimic hpo --resume {}", out.display())),
        "{stdout}"
    );
    assert!(!stderr.contains("error:"), "{stderr}");
    // The summary of the cycles done is written; resuming finishes the same search.
    assert!(out.join("summary.md").is_file());
    let history = read(&out.join("history.jsonl"));
    assert!(history.lines().count() < 9, "the stop came before the end");
    let resumed = Command::new(binary())
        .args(["hpo", "--resume"])
        .arg(&out)
        .args(["--cycles", "8"])
        .output()
        .unwrap();
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let config = HpoConfig::parse(&text, "test", tmp.path(), "test").unwrap();
    let straight = tmp.path().join("straight");
    let mut search = Search::new(config.clone(), &straight).unwrap();
    let mut pool =
        RunnerPool::new(build_runners(&config.runner, config.objective).unwrap()).unwrap();
    search
        .run(&mut OfflineProposer, &mut pool, 8, &mut std::io::sink())
        .unwrap();
    for file in ["history.jsonl", "state.json", "best.toml"] {
        assert_eq!(read(&out.join(file)), read(&straight.join(file)), "{file}");
    }
}

#[test]
fn sigterm_stops_the_search_between_trials_with_143_and_it_resumes() {
    stopped_cleanly("-TERM", "SIGTERM", 143);
}

#[test]
fn sigint_stops_the_search_with_130() {
    stopped_cleanly("-INT", "SIGINT", 130);
}

/// `timeout` sends its SIGTERM to the command and to its process group: a second SIGTERM is
/// the same request, not the at-once end a second Ctrl-C is.
#[test]
fn a_repeated_sigterm_still_stops_the_search_cleanly() {
    stopped_cleanly_after(&["-TERM", "-TERM"], "SIGTERM", 143);
}

#[test]
fn a_second_sigint_ends_the_search_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    // Trials of 5 s: both signals land during one, even on a loaded 2-core machine (with 2 s
    // trials a clean run once saw the trial end between the signals and the search stop with
    // 143).
    let (mut child, _) = spawn_search(tmp.path(), &out, 5000);
    wait_for_cycles(&out, 1);
    // `history.jsonl` is the first file a commit writes; the rest of the commit and the next
    // cycle's planning come before its first trial. A CI run once sent SIGTERM in that gap, so
    // the search stopped cleanly (143) before the SIGINT: give the next trial 1.5 s to start.
    std::thread::sleep(Duration::from_millis(1500));
    send(&child, "-TERM");
    // Two signals pending at once would be delivered as one.
    std::thread::sleep(Duration::from_millis(200));
    let started = Instant::now();
    send(&child, "-INT");
    let status = child.wait().unwrap();
    assert!(
        started.elapsed() < Duration::from_millis(1500),
        "not at once"
    );
    // Ended by the signal's default action, not by a clean stop.
    assert_eq!((status.code(), status.signal()), (None, Some(2)));
    // The committed state is whole: the search resumes from it.
    let resumed = Search::resume(&out, None).unwrap();
    assert_eq!(resumed.cycles_done(), 0);
}
