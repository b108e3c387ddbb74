//! The watch over a world's control connections while a rank waits for its GPU (src/world/watch.rs),
//! with ranks as threads on the loopback: a peer that dies, aborts or outlasts the timeout during
//! the wait calls the loss handler (in a run: the NCCL abort that ends the wait) and leaves one
//! line; a peer's report queued meanwhile is neither a loss nor consumed; outside a wait nothing is
//! done.

use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use instantmimic::world::{Control, Host, RendezvousAddress, Watch, WorldError, join};

const FINGERPRINT: u64 = 7;
const BOUND: Duration = Duration::from_secs(10);

/// A world of two on the loopback: rank 0's control and rank 1's.
fn world_of_two() -> (Control, Control) {
    let host = Host::bind(0).expect("a free port");
    let port = host.port();
    let leader = thread::spawn(move || host.gather(2, FINGERPRINT, b"id", BOUND));
    let address = RendezvousAddress {
        host: "127.0.0.1".to_owned(),
        port,
    };
    let (_, member) = join(&address, 2, 1, FINGERPRINT, BOUND).expect("rank 1 joins");
    (
        leader.join().expect("thread").expect("the world forms"),
        member,
    )
}

/// A watch whose loss handler sends on the returned channel.
fn watch(control: &Control, timeout: Duration) -> (Watch, mpsc::Receiver<Instant>) {
    let (send, losses) = mpsc::channel();
    let watch = Watch::start(control, timeout, move || {
        let _ = send.send(Instant::now());
    })
    .expect("the watch starts");
    (watch, losses)
}

#[test]
fn a_rank_that_dies_during_the_wait_is_named_and_the_wait_released() {
    let (leader, member) = world_of_two();
    let (watch, losses) = watch(&leader, BOUND);
    watch.enter();
    let died = Instant::now();
    drop(member);
    let released = losses.recv_timeout(BOUND).expect("the loss handler runs");
    assert!(
        released - died < Duration::from_secs(2),
        "{:?}",
        released - died
    );
    match watch.leave() {
        Some(e @ WorldError::RankLost { rank: 1, .. }) => {
            let text = e.to_string();
            assert!(
                text.contains("rank 1 closed its connection during an iteration"),
                "{text}"
            );
        }
        other => panic!("expected rank 1 lost, got {other:?}"),
    }
}

#[test]
fn rank_0_lost_during_a_members_wait_is_named() {
    let (leader, member) = world_of_two();
    let (watch, losses) = watch(&member, BOUND);
    watch.enter();
    drop(leader);
    losses.recv_timeout(BOUND).expect("the loss handler runs");
    assert!(matches!(
        watch.leave(),
        Some(WorldError::RankLost { rank: 0, .. })
    ));
}

#[test]
fn an_abort_during_the_wait_carries_its_reason() {
    let (leader, mut member) = world_of_two();
    let (watch, losses) = watch(&leader, BOUND);
    watch.enter();
    member.abort("its GPU ran out of memory");
    losses.recv_timeout(BOUND).expect("the loss handler runs");
    let verdict = watch.leave().expect("a verdict").to_string();
    assert_eq!(verdict, "rank 1 stopped: its GPU ran out of memory");
}

#[test]
fn a_report_queued_during_the_wait_is_no_loss_and_is_left_for_the_step() {
    let (mut leader, mut member) = world_of_two();
    let (watch, losses) = watch(&leader, BOUND);
    watch.enter();
    // Rank 1 finishes its iteration first and reports; rank 0's GPU is still busy.
    let member = thread::spawn(move || {
        let decision = member
            .exchange(b"report of rank 1", |_| unreachable!(), BOUND)
            .expect("a decision");
        (member, decision)
    });
    thread::sleep(Duration::from_millis(300));
    assert!(watch.leave().is_none());
    assert!(losses.try_recv().is_err(), "no loss");
    // The control step reads the report whole, with its own deadline.
    let decision = leader
        .exchange(
            b"report of rank 0",
            |reports| {
                assert_eq!(reports[1], b"report of rank 1");
                b"go".to_vec()
            },
            BOUND,
        )
        .expect("the step");
    assert_eq!(decision, b"go");
    let (_member, decision) = member.join().expect("thread");
    assert_eq!(decision, b"go");
    // A later wait watches afresh: rank 1 dying now is a loss.
    watch.enter();
    drop(_member);
    losses.recv_timeout(BOUND).expect("the loss handler runs");
    assert!(matches!(
        watch.leave(),
        Some(WorldError::RankLost { rank: 1, .. })
    ));
}

#[test]
fn a_wait_past_the_timeout_is_a_hang() {
    let (leader, _member) = world_of_two();
    let (watch, losses) = watch(&leader, Duration::from_secs(1));
    let started = Instant::now();
    watch.enter();
    let released = losses.recv_timeout(BOUND).expect("the loss handler runs");
    let waited = released - started;
    assert!(
        waited >= Duration::from_secs(1) && waited < Duration::from_secs(3),
        "{waited:?}"
    );
    let verdict = watch.leave().expect("a verdict").to_string();
    assert!(verdict.contains("did not finish within 1 s"), "{verdict}");
}

#[test]
fn outside_a_wait_a_loss_is_left_to_the_control_step() {
    let (mut leader, member) = world_of_two();
    let (watch, losses) = watch(&leader, BOUND);
    drop(member);
    thread::sleep(Duration::from_millis(300));
    assert!(losses.try_recv().is_err(), "no loss handled outside a wait");
    assert!(watch.leave().is_none());
    // The step names it, as before.
    let e = leader
        .exchange(b"", |_| unreachable!(), BOUND)
        .expect_err("rank 1 is gone");
    assert!(matches!(e, WorldError::RankLost { rank: 1, .. }), "{e}");
}
