//! Shared pieces of the HPO tests: a small synthetic search configuration, a scripted
//! chat-completions server on 127.0.0.1, and helpers to read a run directory.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use instantmimic::hpo::HpoConfig;

/// A small search against the synthetic objective: a log float that may widen, an int, a bool.
/// `agent` is the `[agent]` section (and its sub-tables); `search_extra` goes into `[search]`.
pub fn config_text(agent: &str, search_extra: &str, runner_extra: &str) -> String {
    format!(
        r#"
[task]
name = "test"
description = "A synthetic test task."

[objective]
budget_s = 20.0

[search]
cycles = 4
seeds = [0, 1, 2]
max_candidates = 4
{search_extra}

[[search.param]]
name = "ppo.learning_rate"
type = "float"
min = 1e-4
max = 1e-2
log = true

[[search.param]]
name = "ppo.kl_threshold"
type = "float"
min = 0.002
max = 0.03
log = true
widen_to = [0.0005, 0.5]

[[search.param]]
name = "ppo.horizon"
type = "int"
min = 4
max = 64

[[search.param]]
name = "obs.root_target"
type = "bool"

[runner]
kind = "synthetic"
{runner_extra}

[runner.synthetic]
base_s = 2.0
noise = 0.05

[[runner.synthetic.term]]
name = "ppo.learning_rate"
optimum = 6.25e-4
width = 0.7
log = true
fail_beyond = 2.5

[[runner.synthetic.term]]
name = "ppo.kl_threshold"
optimum = 0.12
width = 1.5
log = true

[[runner.synthetic.term]]
name = "ppo.horizon"
optimum = 8
width = 30.0

[[runner.synthetic.term]]
name = "obs.root_target"
optimum = true
penalty = 0.3

[base.values.ppo]
learning_rate = 5e-4
kl_threshold = 0.008
horizon = 32
clip = 0.2

[base.values.obs]
root_target = false

{agent}
"#
    )
}

pub fn offline_config(search_extra: &str, runner_extra: &str) -> HpoConfig {
    let text = config_text(
        "[agent]\nbackend = \"offline\"\n",
        search_extra,
        runner_extra,
    );
    HpoConfig::parse(&text, "test", Path::new("."), "test").expect("the test configuration loads")
}

pub fn binary() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_instantmimic"))
}

/// Every file under `dir`, recursively.
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("readable directory").flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

pub fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A valid six-heading strategy.
pub fn valid_plan(next: &str) -> String {
    format!(
        "# Current Strategy\nTest strategy.\n## Best Baseline\nbaseline\n## What Seems Promising\n\
         kl\n## What To Avoid\nnothing\n## Next Experiment\n{next}\n## Wildcards\nnone\n"
    )
}

// ---- the scripted chat-completions server ----------------------------------------------

/// One scripted answer. `{auth}` in the content is replaced by the request's Authorization
/// value (a server that echoes the key back).
#[derive(Clone)]
pub struct Scripted {
    pub status: u16,
    /// The assistant message content (wrapped into a chat completion when status is 200), or
    /// the raw body otherwise.
    pub content: String,
    pub delay: Duration,
}

impl Scripted {
    pub fn reply(content: impl Into<String>) -> Self {
        Scripted {
            status: 200,
            content: content.into(),
            delay: Duration::ZERO,
        }
    }
    pub fn status(status: u16, body: &str) -> Self {
        Scripted {
            status,
            content: body.to_string(),
            delay: Duration::ZERO,
        }
    }
    pub fn delayed(content: impl Into<String>, delay: Duration) -> Self {
        Scripted {
            status: 200,
            content: content.into(),
            delay,
        }
    }
}

/// A request the server saw.
#[derive(Clone, Debug)]
pub struct Seen {
    pub path: String,
    pub authorization: Option<String>,
    pub body: serde_json::Value,
}

impl Seen {
    pub fn prompt(&self) -> String {
        self.body["messages"][0]["content"]
            .as_str()
            .unwrap_or_default()
            .to_string()
    }
}

/// An HTTP/1.1 server on 127.0.0.1 that answers each request with the next scripted reply.
/// It stops by itself when dropped or after a minute.
pub struct MockServer {
    pub url: String,
    pub seen: Arc<Mutex<Vec<Seen>>>,
    stop: Arc<AtomicBool>,
}

impl MockServer {
    pub fn start(script: Vec<Scripted>) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind 127.0.0.1:0");
        listener
            .set_nonblocking(true)
            .expect("non-blocking listener");
        let url = format!("http://{}/v1", listener.local_addr().expect("address"));
        let seen = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let script = Arc::new(Mutex::new(script.into_iter()));
        let (seen2, stop2) = (seen.clone(), stop.clone());
        std::thread::spawn(move || {
            let deadline = Instant::now() + Duration::from_secs(60);
            let mut served = 0;
            while !stop2.load(Ordering::Relaxed) && Instant::now() < deadline && served < 200 {
                match listener.accept() {
                    Ok((stream, _)) => {
                        served += 1;
                        let (script, seen) = (script.clone(), seen2.clone());
                        std::thread::spawn(move || serve(stream, &script, &seen));
                    }
                    Err(_) => std::thread::sleep(Duration::from_millis(5)),
                }
            }
        });
        MockServer { url, seen, stop }
    }

    pub fn seen(&self) -> Vec<Seen> {
        self.seen.lock().map(|s| s.clone()).unwrap_or_default()
    }
}

impl Drop for MockServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

type Script = Mutex<std::vec::IntoIter<Scripted>>;

fn serve(stream: TcpStream, script: &Script, seen: &Mutex<Vec<Seen>>) {
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_read_timeout(Some(Duration::from_secs(10)));
    let mut reader = BufReader::new(match stream.try_clone() {
        Ok(s) => s,
        Err(_) => return,
    });
    let mut request_line = String::new();
    if reader.read_line(&mut request_line).is_err() {
        return;
    }
    let path = request_line
        .split_whitespace()
        .nth(1)
        .unwrap_or_default()
        .to_string();
    let mut length = 0usize;
    let mut authorization = None;
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).is_err() || line.trim().is_empty() {
            break;
        }
        if let Some((name, value)) = line.split_once(':') {
            match name.trim().to_ascii_lowercase().as_str() {
                "content-length" => length = value.trim().parse().unwrap_or(0),
                "authorization" => authorization = Some(value.trim().to_string()),
                _ => {}
            }
        }
    }
    let mut body = vec![0u8; length];
    if reader.read_exact(&mut body).is_err() {
        return;
    }
    let body: serde_json::Value = serde_json::from_slice(&body).unwrap_or(serde_json::Value::Null);
    let next = script.lock().ok().and_then(|mut s| s.next());
    if let Ok(mut seen) = seen.lock() {
        seen.push(Seen {
            path,
            authorization: authorization.clone(),
            body,
        });
    }
    let next = next.unwrap_or_else(|| Scripted::status(503, "{\"error\":\"script exhausted\"}"));
    std::thread::sleep(next.delay);
    let key = authorization
        .as_deref()
        .and_then(|a| a.strip_prefix("Bearer "))
        .unwrap_or_default();
    let content = next.content.replace("{auth}", key);
    let payload = if next.status == 200 {
        serde_json::json!({
            "id": "test",
            "object": "chat.completion",
            "choices": [{"index": 0, "message": {"role": "assistant", "content": content}}],
        })
        .to_string()
    } else {
        content
    };
    let response = format!(
        "HTTP/1.1 {} Scripted\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{payload}",
        next.status,
        payload.len()
    );
    let mut stream = stream;
    let _ = stream.write_all(response.as_bytes());
    let _ = stream.flush();
}
