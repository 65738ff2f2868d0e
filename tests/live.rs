//! `rigidsim live` (issue 54) through its WebSocket, as any client would
//! drive it: the pace of the wall clock, a grabbed body dragged up, every
//! kind of bad message answered with an error while the run goes on, the
//! token and the origin check, and the recorded `inputs.jsonl` replayed by
//! `rigidsim run --inputs` to the live run's state hash on 1 and 2 ranks.

mod common;

use serde_json::{Value, json};
use std::io::BufRead;
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, ExitStatus, Stdio};
use std::time::{Duration, Instant};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

type Socket = WebSocket<MaybeTlsStream<TcpStream>>;

/// A live run of a scene on a free port, its output folder and address.
struct Live {
    child: Child,
    out: PathBuf,
    url: String,
}

impl Live {
    fn start(scene: &Path, out: &Path, extra: &[&str]) -> Live {
        let mut child = common::command(env!("CARGO_BIN_EXE_rigidsim"))
            .arg("live")
            .arg(scene)
            .args(["--port", "0", "--no-render", "--out"])
            .arg(out)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(out.with_extension("stderr")).unwrap())
            .spawn()
            .expect("cannot start rigidsim live");
        let mut first = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut first)
            .unwrap();
        let url = first.trim().to_string();
        assert!(url.starts_with("http://"), "no URL printed: {first:?}");
        Live {
            child,
            out: out.to_path_buf(),
            url,
        }
    }

    /// As `start`, under `mpirun -np np` (rank 0 prints the URL).
    fn start_under_mpirun(np: u32, scene: &Path, out: &Path) -> Live {
        let mut child = common::command("mpirun")
            .args(["--oversubscribe", "-np", &np.to_string()])
            .arg(env!("CARGO_BIN_EXE_rigidsim"))
            .arg("live")
            .arg(scene)
            .args(["--port", "0", "--no-render", "--out"])
            .arg(out)
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(out.with_extension("stderr")).unwrap())
            .spawn()
            .expect("cannot start mpirun");
        let mut reader = std::io::BufReader::new(child.stdout.take().unwrap());
        let url = loop {
            let mut line = String::new();
            assert!(reader.read_line(&mut line).unwrap() > 0, "no URL printed");
            if line.trim().starts_with("http://") {
                break line.trim().to_string();
            }
        };
        // The ranks' other output goes on; nobody reads it.
        std::thread::spawn(move || std::io::copy(&mut reader, &mut std::io::sink()));
        Live {
            child,
            out: out.to_path_buf(),
            url,
        }
    }

    /// host:port of the server.
    fn authority(&self) -> &str {
        let rest = &self.url["http://".len()..];
        &rest[..rest.find('/').unwrap()]
    }

    fn connect(&self) -> Socket {
        let (mut socket, _) = tungstenite::connect(format!("ws://{}/ws", self.authority()))
            .expect("WebSocket upgrade refused");
        if let MaybeTlsStream::Plain(s) = socket.get_mut() {
            s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        }
        socket
    }

    fn wait(&mut self, limit: Duration) -> ExitStatus {
        let until = Instant::now() + limit;
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s;
            }
            if Instant::now() > until {
                let _ = self.child.kill();
                panic!("rigidsim live still running after {limit:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn summary(&self) -> Value {
        let text = std::fs::read_to_string(self.out.join("summary.json")).unwrap_or_else(|e| {
            panic!(
                "no summary.json: {e}; stderr: {}",
                std::fs::read_to_string(self.out.with_extension("stderr")).unwrap_or_default()
            )
        });
        serde_json::from_str(&text).unwrap()
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn receive(socket: &mut Socket) -> Value {
    loop {
        match socket.read().expect("the connection broke") {
            Message::Text(t) => return serde_json::from_str(t.as_str()).unwrap(),
            Message::Close(_) => panic!("closed by the server"),
            _ => continue,
        }
    }
}

/// The next message of `kind`, skipping the others (states between).
fn receive_kind(socket: &mut Socket, kind: &str) -> Value {
    loop {
        let m = receive(socket);
        if m["type"] == kind {
            return m;
        }
    }
}

fn send(socket: &mut Socket, message: &Value) {
    socket
        .send(Message::Text(message.to_string().into()))
        .unwrap();
}

fn position(state: &Value, body: usize) -> [f64; 3] {
    let b = &state["bodies"][body];
    [0, 1, 2].map(|i| b[i].as_f64().unwrap())
}

/// Simulated time keeps within a quarter of the wall clock over 2 s on a
/// light scene; the scene message describes the bodies; a push lifts the
/// cube; paused, time stands still; a reset puts the cube back at its
/// start; a stop message ends the run with `end_reason = "stopped"`, a
/// checkpoint and the inputs, each recorded, with the last step.
#[test]
fn a_live_run_keeps_pace_with_the_wall_clock_and_stops_on_request() {
    let dir = tempfile::tempdir().unwrap();
    let mut live = Live::start(
        &common::bundled("render_check.toml"),
        &dir.path().join("pace"),
        &[],
    );
    let mut socket = live.connect();
    let scene = receive(&mut socket);
    assert_eq!(scene["type"], "scene");
    assert_eq!(scene["bodies"], 2);
    assert_eq!(scene["body_kind"], json!(["fixed", "dynamic"]));
    assert_eq!(scene["objects"].as_array().unwrap().len(), 2);
    let first = receive_kind(&mut socket, "state");
    let (t0, wall0) = (first["t"].as_f64().unwrap(), Instant::now());
    let mut last = first;
    while wall0.elapsed() < Duration::from_secs(2) {
        last = receive_kind(&mut socket, "state");
    }
    let sim = last["t"].as_f64().unwrap() - t0;
    let wall = wall0.elapsed().as_secs_f64();
    assert!(
        (sim - wall).abs() < 0.25 * wall,
        "{sim:.3} s simulated in {wall:.3} s of wall time"
    );
    assert_eq!(last["bodies"].as_array().unwrap().len(), 2);

    // A push up at the resting cube's centre (1 kg, 2 m/s: about 0.2 m up).
    let p = position(&last, 1);
    send(
        &mut socket,
        &json!({"type": "push", "body": 1, "point": p, "impulse": [0.0, 0.0, 2.0]}),
    );
    let mut highest = p[2];
    let pushed = Instant::now();
    while pushed.elapsed() < Duration::from_millis(400) {
        highest = highest.max(position(&receive_kind(&mut socket, "state"), 1)[2]);
    }
    assert!(
        highest > p[2] + 0.1,
        "pushed up from {:.3}, rose to {highest:.3}",
        p[2]
    );

    // Paused, simulated time stands still; resumed, it goes on.
    send(&mut socket, &json!({"type": "pause"}));
    let paused = loop {
        let s = receive_kind(&mut socket, "state");
        if s["paused"] == true {
            break s;
        }
    };
    std::thread::sleep(Duration::from_millis(300));
    let still = receive_kind(&mut socket, "state");
    assert_eq!(still["t"], paused["t"], "time went on while paused");
    send(&mut socket, &json!({"type": "resume"}));
    loop {
        let s = receive_kind(&mut socket, "state");
        if s["t"].as_f64().unwrap() > paused["t"].as_f64().unwrap() {
            assert_eq!(s["paused"], false);
            break;
        }
    }

    // Reset: the cube back at the scene's start (0, 0, 0.45), time going on.
    let before = receive_kind(&mut socket, "state");
    send(&mut socket, &json!({"type": "reset"}));
    let counted = before["inputs"].as_u64().unwrap() + 1;
    let reset = loop {
        let s = receive_kind(&mut socket, "state");
        if s["inputs"].as_u64().unwrap() >= counted {
            break s;
        }
    };
    assert!(reset["t"].as_f64().unwrap() >= before["t"].as_f64().unwrap());
    let back = position(&reset, 1);
    assert!(
        back[0].abs() < 1e-6 && back[1].abs() < 1e-6 && (back[2] - 0.45).abs() < 0.01,
        "after reset the cube is at {back:?}"
    );
    send(&mut socket, &json!({"type": "stop"}));
    assert_eq!(receive_kind(&mut socket, "end")["end_reason"], "stopped");
    let status = live.wait(Duration::from_secs(10));
    assert!(status.success(), "{status:?}");
    let s = live.summary();
    assert_eq!(s["end_reason"], "stopped");
    assert!(live.out.join("checkpoint.bin").is_file());
    let inputs = std::fs::read_to_string(live.out.join("inputs.jsonl")).unwrap();
    let kinds: Vec<String> = inputs
        .lines()
        .map(|l| {
            serde_json::from_str::<Value>(l).unwrap()["type"]
                .as_str()
                .unwrap()
                .into()
        })
        .collect();
    assert_eq!(
        kinds,
        ["push", "pause", "resume", "reset", "stop", "end"],
        "{inputs}"
    );
    let end: Value = serde_json::from_str(inputs.lines().last().unwrap()).unwrap();
    assert_eq!(end["step"], s["steps"]);
    // The push and the reset replay to the live run's state.
    let replayed = dir.path().join("pace_replayed");
    let o = common::command(env!("CARGO_BIN_EXE_rigidsim"))
        .arg("run")
        .arg(common::bundled("render_check.toml"))
        .arg("--inputs")
        .arg(live.out.join("inputs.jsonl"))
        .args(["--no-render", "--no-progress", "--out"])
        .arg(&replayed)
        .output()
        .unwrap();
    assert!(o.status.success(), "{o:?}");
    let r: Value =
        serde_json::from_str(&std::fs::read_to_string(replayed.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(r["state_hash"], s["state_hash"]);
}

/// A resting cube grabbed at its centre and dragged 0.5 m up rises (the
/// hand's spring holds it about g / ω² below the target); a client that
/// disconnects mid-grab releases its grab. The recorded inputs then replay
/// with `rigidsim run --inputs` to the live run's state hash, alone and on
/// two ranks with every stage distributed.
#[test]
fn a_dragged_body_rises_and_the_recorded_inputs_replay_to_the_same_hash() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::bundled("render_check.toml");
    let mut live = Live::start(&scene, &dir.path().join("drag"), &[]);
    let mut socket = live.connect();
    receive_kind(&mut socket, "scene");
    // The cube lands at about 0.29 s and comes to rest.
    let resting = loop {
        let s = receive_kind(&mut socket, "state");
        if s["resting"] == json!([1]) {
            break s;
        }
        assert!(s["t"].as_f64().unwrap() < 5.0, "the cube never rests: {s}");
    };
    let start = position(&resting, 1);
    let target = [start[0], start[1], start[2] + 0.5];
    send(
        &mut socket,
        &json!({"type": "grab", "body": 1, "point": start}),
    );
    send(&mut socket, &json!({"type": "drag", "target": target}));
    let wall = Instant::now();
    let mut highest = start[2];
    while wall.elapsed() < Duration::from_millis(1500) {
        let s = receive_kind(&mut socket, "state");
        highest = highest.max(position(&s, 1)[2]);
    }
    assert!(
        highest > start[2] + 0.4,
        "dragged 0.5 m up from z = {:.3}, the cube rose only to {highest:.3}",
        start[2]
    );
    // Gone mid-grab: the run releases the hand and the cube falls back.
    drop(socket);
    let mut watcher = live.connect();
    let fell = Instant::now();
    loop {
        let s = receive_kind(&mut watcher, "state");
        if position(&s, 1)[2] < start[2] + 0.05 {
            break;
        }
        assert!(
            fell.elapsed() < Duration::from_secs(5),
            "the cube is still held: {s}"
        );
    }
    send(&mut watcher, &json!({"type": "stop"}));
    assert!(live.wait(Duration::from_secs(10)).success());
    let inputs = std::fs::read_to_string(live.out.join("inputs.jsonl")).unwrap();
    let kinds: Vec<String> = inputs
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap()["type"].to_string())
        .collect();
    assert_eq!(
        kinds,
        ["\"grab\"", "\"drag\"", "\"release\"", "\"stop\"", "\"end\""],
        "{inputs}"
    );
    let s = live.summary();
    let hash = s["state_hash"].as_str().unwrap().to_string();
    let sim_time = s["sim_time_s"].as_f64().unwrap().to_string();

    // Alone, to the live run's sim_time_s.
    let replay = |np: Option<u32>, name: &str, extra: &[&str]| -> Value {
        let out = dir.path().join(name);
        let bin = env!("CARGO_BIN_EXE_rigidsim");
        let mut cmd = match np {
            None => common::command(bin),
            Some(np) => {
                let mut c = common::command("mpirun");
                c.args(["--oversubscribe", "-np", &np.to_string(), bin]);
                c
            }
        };
        let o = cmd
            .arg("run")
            .arg(&scene)
            .arg("--inputs")
            .arg(live.out.join("inputs.jsonl"))
            .args(["--no-render", "--no-progress", "--out"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{o:?}");
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
    };
    let alone = replay(None, "replay1", &["--duration", &sim_time]);
    assert_eq!(alone["state_hash"], hash.as_str(), "replay alone");
    assert_eq!(alone["steps"], s["steps"]);
    // On two ranks, every stage on the worker, to the recorded last step.
    let two = replay(Some(2), "replay2", &["--force-distribute"]);
    assert_eq!(two["state_hash"], hash.as_str(), "replay on 2 ranks");
    assert_eq!(two["end_reason"], "duration");

    // Stopped while the cube is held, then resumed with the inputs: the
    // hand is taken up from the recording and the run ends as the live one.
    let step_of = |kind: &str| {
        inputs
            .lines()
            .map(|l| serde_json::from_str::<Value>(l).unwrap())
            .find(|v| v["type"] == kind)
            .unwrap()["step"]
            .as_u64()
            .unwrap()
    };
    let held = (step_of("grab") + step_of("release")) / 2;
    let until = (held as f64 * 0.01).to_string();
    let first = replay(
        None,
        "resumed",
        &["--duration", &until, "--checkpoint-every", &until],
    );
    assert_eq!(first["steps"], held);
    let checkpoint = dir.path().join("resumed/checkpoint.bin");
    let resumed = replay(None, "resumed", &["--resume", checkpoint.to_str().unwrap()]);
    assert_eq!(resumed["state_hash"], hash.as_str(), "resumed mid-grab");
}

/// Every kind of bad message gets an error on its socket and the run goes
/// on; a WebSocket from another site's page is refused; SIGINT ends the
/// run as `interrupted` with status 130.
#[test]
fn bad_messages_are_answered_with_errors_and_the_run_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let mut live = Live::start(
        &common::bundled("render_check.toml"),
        &dir.path().join("bad"),
        &[],
    );
    let mut socket = live.connect();
    receive_kind(&mut socket, "scene");
    let t_before = receive_kind(&mut socket, "state")["t"].as_f64().unwrap();
    let oversized = format!(r#"{{"type":"pause","pad":"{}"}}"#, "x".repeat(5000));
    let bad: Vec<(String, &str)> = vec![
        ("this is not JSON".into(), "not a message"),
        (r#"{"type":"teleport"}"#.into(), "not a message"),
        (
            r#"{"type":"grab","body":99,"point":[0,0,0]}"#.into(),
            "no body 99",
        ),
        (
            r#"{"type":"grab","body":0,"point":[0,0,0]}"#.into(),
            "fixed",
        ),
        (
            r#"{"type":"drag","target":[NaN,0,0]}"#.into(),
            "not a message",
        ),
        (
            r#"{"type":"grab","body":1,"point":[1e300,0,0]}"#.into(),
            "point",
        ),
        (
            r#"{"type":"push","body":1,"point":[0,0,0.45],"impulse":[0,0,1e15]}"#.into(),
            "bound",
        ),
        (
            r#"{"type":"drag","target":[0,0,1]}"#.into(),
            "without a grab",
        ),
        (oversized, "at most 4096"),
    ];
    for (text, says) in &bad {
        socket.send(Message::Text(text.clone().into())).unwrap();
        let e = receive_kind(&mut socket, "error");
        let message = e["message"].as_str().unwrap();
        assert!(message.contains(says), "{text:.60}: {message}");
    }
    socket.send(Message::Binary(vec![1, 2, 3].into())).unwrap();
    assert!(
        receive_kind(&mut socket, "error")["message"]
            .as_str()
            .unwrap()
            .contains("binary")
    );
    // A flood: the messages over the allowance are refused, each with an error.
    for _ in 0..600 {
        send(&mut socket, &json!({"type": "resume"}));
    }
    let flooded = receive_kind(&mut socket, "error");
    assert!(
        flooded["message"].as_str().unwrap().contains("too many"),
        "{flooded}"
    );
    // The run went on, and still answers.
    let later = receive_kind(&mut socket, "state");
    assert!(later["t"].as_f64().unwrap() > t_before, "{later}");
    assert_eq!(later["paused"], false);

    // Another site's page may not open the WebSocket.
    let mut request = tungstenite::client::IntoClientRequest::into_client_request(format!(
        "ws://{}/ws",
        live.authority()
    ))
    .unwrap();
    request
        .headers_mut()
        .insert("Origin", "http://elsewhere.example".parse().unwrap());
    assert!(
        tungstenite::connect(request).is_err(),
        "foreign origin admitted"
    );

    // Ctrl-C ends the live run as it ends a run.
    // SAFETY: kill(2) on our own child, not yet reaped.
    unsafe { libc::kill(live.child.id() as libc::pid_t, libc::SIGINT) };
    let status = live.wait(Duration::from_secs(10));
    assert_eq!(status.code(), Some(130), "{status:?}");
    assert_eq!(live.summary()["end_reason"], "interrupted");
}

/// Under `mpirun -np 2`, rank 0 serves the live run with a worker beside
/// it; a grab, then a stop, end it with both ranks' accounts in the summary.
#[test]
fn a_live_run_under_mpirun_serves_from_rank_0() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/tumbling_cubes.toml");
    let mut live = Live::start_under_mpirun(2, &scene, &dir.path().join("mpi"));
    let mut socket = live.connect();
    assert_eq!(receive_kind(&mut socket, "scene")["bodies"], 5);
    let s = receive_kind(&mut socket, "state");
    let p = position(&s, 2);
    send(&mut socket, &json!({"type": "grab", "body": 2, "point": p}));
    send(
        &mut socket,
        &json!({"type": "drag", "target": [p[0], p[1], p[2] + 0.2]}),
    );
    let until = Instant::now() + Duration::from_millis(500);
    while Instant::now() < until {
        receive_kind(&mut socket, "state");
    }
    send(&mut socket, &json!({"type": "stop"}));
    assert_eq!(receive_kind(&mut socket, "end")["end_reason"], "stopped");
    live.wait(Duration::from_secs(20));
    let s = live.summary();
    assert_eq!(s["end_reason"], "stopped");
    assert_eq!(s["per_rank"].as_array().unwrap().len(), 2, "{s}");
}

/// Bound beyond loopback, the page and the WebSocket need the printed
/// URL's token.
#[test]
fn beyond_loopback_every_request_needs_the_token() {
    let dir = tempfile::tempdir().unwrap();
    let live = Live::start(
        &common::bundled("render_check.toml"),
        &dir.path().join("token"),
        &["--bind", "0.0.0.0"],
    );
    let token = live
        .url
        .split("token=")
        .nth(1)
        .expect("no token in the URL");
    assert_eq!(token.len(), 32);
    // The URL names this host, as other PCs reach it; the test uses loopback.
    let port = live.authority().rsplit(':').next().unwrap();
    let at = format!("127.0.0.1:{port}");
    let get = |path: &str| {
        use std::io::{Read, Write};
        let mut s = TcpStream::connect(&at).unwrap();
        write!(
            s,
            "GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut r = String::new();
        let _ = s.read_to_string(&mut r);
        r
    };
    assert!(get("/").starts_with("HTTP/1.1 403"));
    assert!(get("/?token=wrong").starts_with("HTTP/1.1 403"));
    let page = get(&format!("/?token={token}"));
    assert!(page.starts_with("HTTP/1.1 200"), "{page:.200}");
    assert!(page.contains("rigidsim live"));
    assert!(tungstenite::connect(format!("ws://{at}/ws")).is_err());
    assert!(tungstenite::connect(format!("ws://{at}/ws?token={token}")).is_ok());
}

/// A recorded live run whose held body strikes the others (a floor, a
/// neighbour) while held, and a push: replayed alone and on two ranks with
/// every group stepped on the worker, it ends on one state hash. The
/// hand's force must reach the worker for that (`Executor::share_forces`):
/// a group that meets an impact integrates again from the impact's time
/// with the step's external forces.
#[test]
fn a_held_body_striking_others_replays_alike_on_one_and_two_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/tumbling_cubes.toml");
    let inputs = dir.path().join("inputs.jsonl");
    std::fs::write(
        &inputs,
        r#"{"step":100,"hand":1,"type":"grab","body":1,"point":[0.0,0.0,0.3]}
{"step":100,"hand":1,"type":"drag","target":[0.0,0.0,-0.5]}
{"step":300,"hand":1,"type":"drag","target":[0.6,0.0,0.0]}
{"step":500,"hand":1,"type":"drag","target":[-0.6,0.2,0.0]}
{"step":650,"hand":3,"type":"push","body":3,"point":[-0.3,0.2,0.4],"impulse":[0.3,0,-0.5]}
{"step":900,"hand":1,"type":"release"}
{"step":1500,"type":"end","end_reason":"stopped"}
"#,
    )
    .unwrap();
    let run = |np: u32, name: &str| -> Value {
        let out = dir.path().join(name);
        let o = common::command("mpirun")
            .args(["--oversubscribe", "-np", &np.to_string()])
            .arg(env!("CARGO_BIN_EXE_rigidsim"))
            .arg("run")
            .arg(&scene)
            .arg("--inputs")
            .arg(&inputs)
            .args([
                "--no-render",
                "--no-progress",
                "--force-distribute",
                "--out",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{o:?}");
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
    };
    let (one, two) = (run(1, "np1"), run(2, "np2"));
    assert_eq!(one["steps"], 1500);
    assert!(two["distributed"]["groups_distributed"].as_u64().unwrap() > 0);
    assert_eq!(one["state_hash"], two["state_hash"]);
    // And the inputs did act: without them the run ends elsewhere.
    let plain = common::rigidsim(&[
        "run",
        scene.to_str().unwrap(),
        "--no-render",
        "--no-progress",
        "--duration",
        "1.5",
        "--out",
        dir.path().join("plain").to_str().unwrap(),
    ]);
    assert!(plain.status.success());
    let plain: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("plain/summary.json")).unwrap(),
    )
    .unwrap();
    assert_ne!(plain["state_hash"], one["state_hash"]);
}

/// The benchmark of docs/live.md, not a check: the wall time from sending a
/// drag message to the first state that reflects it (the first with the
/// drag counted in `inputs`), median and worst over 100 drags, alone and
/// under `mpirun -np 3` (or the rank counts in `LIVE_BENCH_RANKS`), on the
/// scene in `LIVE_BENCH_SCENE` (default `scenes/nuts_and_bolts.toml`):
///
/// `cargo test --release --test live -- --ignored --nocapture drag_latency`
#[test]
#[ignore]
fn drag_latency() {
    let scene = std::env::var_os("LIVE_BENCH_SCENE")
        .map(PathBuf::from)
        .unwrap_or_else(|| common::bundled("nuts_and_bolts.toml"));
    // LIVE_BENCH_RANKS: which rank counts, e.g. "1,3" (the default).
    let ranks: Vec<u32> = std::env::var("LIVE_BENCH_RANKS")
        .unwrap_or_else(|_| "1,3".into())
        .split(',')
        .map(|n| {
            n.trim()
                .parse()
                .expect("LIVE_BENCH_RANKS: rank counts, e.g. 1,3")
        })
        .collect();
    for np in ranks.into_iter().map(|n| (n > 1).then_some(n)) {
        let dir = tempfile::tempdir().unwrap();
        let mut live = match np {
            None => Live::start(&scene, &dir.path().join("bench"), &[]),
            Some(n) => Live::start_under_mpirun(n, &scene, &dir.path().join("bench")),
        };
        let mut socket = live.connect();
        let facts = receive_kind(&mut socket, "scene");
        let body = facts["body_kind"]
            .as_array()
            .unwrap()
            .iter()
            .position(|k| k == "dynamic")
            .unwrap();
        let mut state = receive_kind(&mut socket, "state");
        // Let the scene settle a little, then take hold of a body.
        while state["t"].as_f64().unwrap() < 1.0 {
            state = receive_kind(&mut socket, "state");
        }
        let p = position(&state, body);
        send(
            &mut socket,
            &json!({"type": "grab", "body": body, "point": p}),
        );
        let mut sent = 1u64 + state["inputs"].as_u64().unwrap();
        let mut latencies = Vec::new();
        for k in 0..100 {
            let target = [p[0], p[1], p[2] + 0.1 + 0.002 * (k % 10) as f64];
            send(&mut socket, &json!({"type": "drag", "target": target}));
            sent += 1;
            let clock = Instant::now();
            loop {
                let s = receive_kind(&mut socket, "state");
                if s["inputs"].as_u64().unwrap() >= sent {
                    latencies.push(clock.elapsed().as_secs_f64() * 1e3);
                    state = s;
                    break;
                }
            }
            // Drags at a mouse's pace, out of step with the states.
            std::thread::sleep(Duration::from_micros(7_000 + 1_300 * (k % 7)));
        }
        latencies.sort_by(f64::total_cmp);
        let name = scene.file_name().unwrap().to_string_lossy();
        println!(
            "{name}, {}: drag → state median {:.1} ms, worst {:.1} ms over {} drags; \
             real-time factor {:.2}, worst frame {:.1} ms (frame interval {:.1} ms)",
            np.map_or("alone".to_string(), |n| format!("mpirun -np {n}")),
            latencies[latencies.len() / 2],
            latencies[latencies.len() - 1],
            latencies.len(),
            state["realtime_factor"].as_f64().unwrap(),
            state["worst_frame_s"].as_f64().unwrap() * 1e3,
            state["frame_interval_s"].as_f64().unwrap() * 1e3,
        );
        send(&mut socket, &json!({"type": "stop"}));
        live.wait(Duration::from_secs(30));
    }
}

/// A live run interrupted while a hand holds the cube, then resumed from
/// its checkpoint as a live run into the same folder: the hand still holds
/// the cube, `inputs.jsonl` holds the whole of both, and replayed from the
/// start it ends on the resumed live run's state hash.
#[test]
fn a_resumed_live_run_keeps_its_hands_and_replays_whole() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::bundled("render_check.toml");
    let out = dir.path().join("resumed");
    let mut first = Live::start(&scene, &out, &[]);
    let mut socket = first.connect();
    receive_kind(&mut socket, "scene");
    let s = loop {
        let s = receive_kind(&mut socket, "state");
        if s["resting"] == json!([1]) {
            break s;
        }
    };
    let p = position(&s, 1);
    send(&mut socket, &json!({"type": "grab", "body": 1, "point": p}));
    send(
        &mut socket,
        &json!({"type": "drag", "target": [p[0], p[1], p[2] + 0.3]}),
    );
    loop {
        let s = receive_kind(&mut socket, "state");
        if position(&s, 1)[2] > p[2] + 0.2 {
            break;
        }
    }
    // SAFETY: kill(2) on our own child, not yet reaped.
    unsafe { libc::kill(first.child.id() as libc::pid_t, libc::SIGINT) };
    assert_eq!(first.wait(Duration::from_secs(10)).code(), Some(130));
    drop(socket);
    let checkpoint = out.join("checkpoint.bin");
    let mut second = Live::start(&scene, &out, &["--resume", checkpoint.to_str().unwrap()]);
    let mut socket = second.connect();
    receive_kind(&mut socket, "scene");
    // Still held up by the hand the first live run left holding it.
    let wall = Instant::now();
    while wall.elapsed() < Duration::from_millis(500) {
        let s = receive_kind(&mut socket, "state");
        assert!(position(&s, 1)[2] > p[2] + 0.15, "the cube was let go: {s}");
    }
    send(&mut socket, &json!({"type": "stop"}));
    assert!(second.wait(Duration::from_secs(10)).success());
    let s = second.summary();
    let o = common::command(env!("CARGO_BIN_EXE_rigidsim"))
        .arg("run")
        .arg(&scene)
        .arg("--inputs")
        .arg(out.join("inputs.jsonl"))
        .args(["--no-render", "--no-progress", "--out"])
        .arg(dir.path().join("whole"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{o:?}");
    let whole: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("whole/summary.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(whole["steps"], s["steps"]);
    assert_eq!(whole["state_hash"], s["state_hash"]);
}

/// A bad `inputs.jsonl` is refused before any step, as a bad scene is:
/// exit status 2 and one line naming the file, the line and what is wrong;
/// `live` does not take `--inputs`.
#[test]
fn a_bad_inputs_file_is_refused_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::bundled("render_check.toml");
    for (text, says) in [
        (
            "{\"step\":1,\"type\":\"pause\"}\n{\"step\":2,\"type\":\"fly\"}\n",
            "line 2: unknown variant `fly`",
        ),
        (
            "{\"step\":1,\"hand\":1,\"type\":\"grab\",\"body\":5,\"point\":[0,0,0]}\n",
            "line 1: body: no body 5",
        ),
        (
            "{\"step\":9,\"type\":\"pause\"}\n{\"step\":3,\"type\":\"resume\"}\n",
            "line 2: step 3 comes before",
        ),
        ("{\"type\":\"pause\"}\n", "line 1: no \"step\""),
        ("", "no inputs and no \"end\" line"),
    ] {
        let inputs = dir.path().join("inputs.jsonl");
        std::fs::write(&inputs, text).unwrap();
        let o = common::rigidsim(&[
            "run",
            scene.to_str().unwrap(),
            "--inputs",
            inputs.to_str().unwrap(),
            "--no-render",
            "--out",
            dir.path().join("out").to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{text}: {stderr}");
        assert!(stderr.contains(says), "{text}: {stderr}");
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
    }
    let o = common::rigidsim(&["live", scene.to_str().unwrap(), "--inputs", "x.jsonl"]);
    assert_eq!(o.status.code(), Some(2));
}

/// `--duration` ends a live run by itself, no sooner than the wall clock
/// allows: 0.5 simulated seconds take at least 0.5 s.
#[test]
fn a_live_run_ends_at_its_duration_on_the_wall_clock() {
    let dir = tempfile::tempdir().unwrap();
    let started = Instant::now();
    let mut live = Live::start(
        &common::bundled("render_check.toml"),
        &dir.path().join("duration"),
        &["--duration", "0.5"],
    );
    assert!(live.wait(Duration::from_secs(20)).success());
    let wall = started.elapsed().as_secs_f64();
    let s = live.summary();
    assert_eq!(s["end_reason"], "duration");
    assert_eq!(s["sim_time_s"], 0.5);
    assert!(wall >= 0.5, "0.5 s simulated in {wall:.3} s of wall time");
    // Sampled at the frame interval (1/60 s: every second step of 0.01 s,
    // 26 samples of 2 bodies with t = 0), not at every step (51 samples).
    let rows = std::fs::read_to_string(live.out.join("trajectory.csv"))
        .unwrap()
        .lines()
        .count();
    assert_eq!(rows, 2 * 26 + 1, "{rows} rows with the header");
}

/// Inputs taken at the boundary a live run stops at act on the state it
/// ends with (a reset before a stop, while paused, so that all three are
/// taken at one boundary), and the replay applies them there too.
#[test]
fn a_reset_just_before_the_stop_replays_to_the_same_hash() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::bundled("render_check.toml");
    let mut live = Live::start(&scene, &dir.path().join("last"), &[]);
    let mut socket = live.connect();
    receive_kind(&mut socket, "scene");
    while receive_kind(&mut socket, "state")["t"].as_f64().unwrap() < 0.6 {}
    send(&mut socket, &json!({"type": "pause"}));
    while receive_kind(&mut socket, "state")["paused"] != true {}
    send(&mut socket, &json!({"type": "reset"}));
    send(&mut socket, &json!({"type": "stop"}));
    assert!(live.wait(Duration::from_secs(10)).success());
    let s = live.summary();
    let inputs = std::fs::read_to_string(live.out.join("inputs.jsonl")).unwrap();
    let steps: Vec<u64> = inputs
        .lines()
        .map(|l| {
            serde_json::from_str::<Value>(l).unwrap()["step"]
                .as_u64()
                .unwrap()
        })
        .collect();
    assert!(steps.iter().skip(1).all(|&x| x == steps[1]), "{inputs}");
    let o = common::command(env!("CARGO_BIN_EXE_rigidsim"))
        .arg("run")
        .arg(&scene)
        .arg("--inputs")
        .arg(live.out.join("inputs.jsonl"))
        .args(["--no-render", "--no-progress", "--out"])
        .arg(dir.path().join("replayed"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{o:?}");
    let r: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("replayed/summary.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(r["state_hash"], s["state_hash"], "{inputs}");
}
