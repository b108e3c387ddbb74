//! The rendezvous and the control connections of a world of processes (src/world/), with ranks
//! as threads on the loopback: a world forms and steps together, and every bad world (a missing
//! rank, a duplicate rank, a wrong world size, another configuration, a port in use, no rank 0,
//! a rank killed or hung after the start) ends on every rank with one line, within a bound.

use std::thread;
use std::time::{Duration, Instant};

use instantmimic::world::{Control, Host, RendezvousAddress, WorldError, join};

const FINGERPRINT: u64 = 0x1234_5678_9abc_def0;
/// A failure must arrive well within this (the deadlines below are 1-2 s): no rank hangs.
const BOUND: Duration = Duration::from_secs(20);

fn loopback(port: u16) -> RendezvousAddress {
    RendezvousAddress {
        host: "127.0.0.1".to_owned(),
        port,
    }
}

/// Starts rank 0 on a free port of a world of `size`; returns the port and its thread.
fn start_host(
    size: usize,
    timeout: Duration,
) -> (u16, thread::JoinHandle<Result<Control, WorldError>>) {
    let host = Host::bind(0).expect("a free port");
    let port = host.port();
    let shared = b"the shared bytes".to_vec();
    let thread = thread::spawn(move || host.gather(size, FINGERPRINT, &shared, timeout));
    (port, thread)
}

fn start_member(
    port: u16,
    size: usize,
    rank: usize,
    fingerprint: u64,
    timeout: Duration,
) -> thread::JoinHandle<Result<(Vec<u8>, Control), WorldError>> {
    thread::spawn(move || join(&loopback(port), size, rank, fingerprint, timeout))
}

fn one_line(e: &WorldError) -> String {
    let text = e.to_string();
    assert!(!text.contains('\n'), "one line: {text}");
    text
}

#[test]
fn a_world_of_three_forms_and_steps_together() {
    let (port, host) = start_host(3, Duration::from_secs(10));
    let members: Vec<_> = (1..3)
        .map(|rank| start_member(port, 3, rank, FINGERPRINT, Duration::from_secs(10)))
        .collect();
    let mut leader = host.join().expect("thread").expect("the world forms");
    let mut controls = vec![];
    for member in members {
        let (shared, control) = member.join().expect("thread").expect("joins");
        assert_eq!(shared, b"the shared bytes");
        controls.push(control);
    }
    assert_eq!((leader.rank(), leader.size()), (0, 3));
    for step in 0..5u8 {
        let threads: Vec<_> = controls
            .drain(..)
            .map(|mut c| {
                thread::spawn(move || {
                    let report = [c.rank() as u8, step];
                    let decision = c
                        .exchange(
                            &report,
                            |_| unreachable!("rank 0 decides"),
                            Duration::from_secs(5),
                        )
                        .expect("a decision");
                    (c, decision)
                })
            })
            .collect();
        // Rank 0 sees every report in rank order and decides for all.
        let decision = leader
            .exchange(
                &[0, step],
                |reports| {
                    assert_eq!(reports, &[vec![0, step], vec![1, step], vec![2, step]]);
                    vec![step, 42]
                },
                Duration::from_secs(5),
            )
            .expect("a decision");
        assert_eq!(decision, [step, 42]);
        for t in threads {
            let (c, theirs) = t.join().expect("thread");
            assert_eq!(theirs, decision, "every rank gets rank 0's decision");
            controls.push(c);
        }
    }
}

#[test]
fn a_world_of_one_needs_no_peer() {
    let host = Host::bind(0).expect("a free port");
    let control = host
        .gather(1, FINGERPRINT, b"id", Duration::from_millis(100))
        .expect("a world of one");
    assert_eq!(control.size(), 1);
}

#[test]
fn a_missing_rank_is_named_on_rank_0_and_ends_the_others() {
    let started = Instant::now();
    let (port, host) = start_host(3, Duration::from_secs(1));
    let member = start_member(port, 3, 1, FINGERPRINT, Duration::from_secs(2));
    let e = host.join().expect("thread").err().expect("refused");
    let text = one_line(&e);
    assert!(
        text.contains("rank 2 of 3 did not join within 1 s"),
        "{text}"
    );
    let e = member.join().expect("thread").err().expect("no world");
    let text = one_line(&e);
    assert!(
        text.contains("the world did not form") || text.contains("rank 0"),
        "{text}"
    );
    assert!(started.elapsed() < BOUND);
}

#[test]
fn a_duplicate_rank_is_refused_on_both_sides() {
    let (port, host) = start_host(3, Duration::from_secs(5));
    let first = start_member(port, 3, 1, FINGERPRINT, Duration::from_secs(5));
    thread::sleep(Duration::from_millis(300));
    let second = start_member(port, 3, 1, FINGERPRINT, Duration::from_secs(5));
    let e = host.join().expect("thread").err().expect("refused");
    assert!(one_line(&e).contains("rank 1 joined twice"), "{e}");
    for member in [first, second] {
        let e = member.join().expect("thread").err().expect("refused");
        assert!(one_line(&e).contains("rank 1 joined twice"), "{e}");
    }
}

#[test]
fn a_wrong_world_size_or_configuration_is_refused_with_both_numbers() {
    let (port, host) = start_host(2, Duration::from_secs(5));
    let member = start_member(port, 3, 1, FINGERPRINT, Duration::from_secs(5));
    let e = host.join().expect("thread").err().expect("refused");
    assert!(
        one_line(&e).contains("world of 3 processes, rank 0 for 2"),
        "{e}"
    );
    let e = member.join().expect("thread").err().expect("refused");
    assert!(one_line(&e).contains("same world size"), "{e}");

    let (port, host) = start_host(2, Duration::from_secs(5));
    let member = start_member(port, 2, 1, FINGERPRINT ^ 1, Duration::from_secs(5));
    let e = host.join().expect("thread").err().expect("refused");
    assert!(one_line(&e).contains("another configuration"), "{e}");
    let e = member.join().expect("thread").err().expect("refused");
    assert!(one_line(&e).contains("same configuration"), "{e}");
}

#[test]
fn a_port_in_use_says_to_choose_another() {
    let held = std::net::TcpListener::bind(("0.0.0.0", 0)).expect("a port");
    let port = held.local_addr().expect("address").port();
    let e = Host::bind(port).err().expect("in use");
    let text = one_line(&e);
    assert!(
        text.contains(&format!("port {port}")) && text.contains("choose another port"),
        "{text}"
    );
}

#[test]
fn no_rank_0_is_one_line_after_the_deadline() {
    // A port nothing listens on: bound, then released.
    let port = {
        let l = std::net::TcpListener::bind(("127.0.0.1", 0)).expect("a port");
        l.local_addr().expect("address").port()
    };
    let started = Instant::now();
    let e = join(&loopback(port), 2, 1, FINGERPRINT, Duration::from_secs(1))
        .err()
        .expect("unreachable");
    let text = one_line(&e);
    assert!(
        text.contains("rank 1 could not reach rank 0 at 127.0.0.1:") && text.contains("within 1 s"),
        "{text}"
    );
    assert!(started.elapsed() < BOUND);
}

#[test]
fn a_host_that_does_not_resolve_is_said_at_once() {
    let started = Instant::now();
    let address = RendezvousAddress {
        host: "no-such-host.invalid".to_owned(),
        port: 29500,
    };
    let e = join(&address, 2, 1, FINGERPRINT, Duration::from_secs(60))
        .err()
        .expect("unresolvable");
    assert!(
        one_line(&e).contains("no-such-host.invalid does not resolve"),
        "{e}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(30),
        "not after the deadline"
    );
}

/// A world of three whose rank 2 is then `lost` (its connection dropped, or silent).
fn lose_rank_2(drop_it: bool) {
    let (port, host) = start_host(3, Duration::from_secs(10));
    let one = start_member(port, 3, 1, FINGERPRINT, Duration::from_secs(10));
    let two = start_member(port, 3, 2, FINGERPRINT, Duration::from_secs(10));
    let mut leader = host.join().expect("thread").expect("forms");
    let (_, mut one) = one.join().expect("thread").expect("joins");
    let (_, two) = two.join().expect("thread").expect("joins");
    let started = Instant::now();
    // Rank 2 dies (its process gone closes its socket), or hangs (holds it, says nothing).
    let hung = if drop_it {
        drop(two);
        None
    } else {
        Some(two)
    };
    let member = thread::spawn(move || one.exchange(b"1", |_| vec![], Duration::from_secs(10)));
    let e = leader
        .exchange(b"0", |_| vec![], Duration::from_secs(1))
        .expect_err("rank 2 is lost");
    let text = one_line(&e);
    let cause = if drop_it {
        "rank 2 closed its connection"
    } else {
        "rank 2 sent nothing for 1 s"
    };
    assert!(
        text.contains(cause) && text.contains("every rank stops"),
        "{text}"
    );
    let e = member.join().expect("thread").expect_err("stopped too");
    assert!(one_line(&e).contains(cause), "rank 1 hears why: {e}");
    assert!(started.elapsed() < BOUND);
    drop(hung);
}

#[test]
fn a_killed_rank_ends_the_others_with_its_name() {
    lose_rank_2(true);
}

#[test]
fn a_hung_rank_ends_the_others_after_the_deadline() {
    lose_rank_2(false);
}

#[test]
fn a_lost_rank_0_ends_the_others() {
    let (port, host) = start_host(2, Duration::from_secs(10));
    let member = start_member(port, 2, 1, FINGERPRINT, Duration::from_secs(10));
    let leader = host.join().expect("thread").expect("forms");
    let (_, mut one) = member.join().expect("thread").expect("joins");
    drop(leader);
    let e = one
        .exchange(b"1", |_| vec![], Duration::from_secs(5))
        .expect_err("rank 0 is gone");
    assert!(one_line(&e).contains("rank 0 closed its connection"), "{e}");
}
