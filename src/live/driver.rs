//! The live run on rank 0: a `Driver` of the run loop that paces the
//! steps to the wall clock, takes the clients' inputs at each step boundary
//! (writing each to `inputs.jsonl` with its step), turns them into the
//! step's external forces (`inputs::Hands`) and publishes the bodies'
//! states to the server.

use super::inputs::{self, Hands, Record};
use super::pacing::Pacer;
use super::protocol::{self, Input, SceneFacts, State};
use super::server::{self, Server, Shared};
use rigidsim::body::Activity;
use rigidsim::run::{Driver, RunError};
use rigidsim::scene::Scene;
use rigidsim::step::{Executor, World};
use std::io::{BufWriter, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// How often a paused live run looks for inputs and signals.
const PAUSED_POLL: Duration = Duration::from_millis(10);

pub struct LiveDriver {
    inputs: mpsc::Receiver<(u32, Input)>,
    states: Option<watch::Sender<Arc<str>>>,
    shared: Arc<Shared>,
    server: Option<Server>,
    hands: Hands,
    /// A resumed live run's recorded inputs of its checkpoint's step, to
    /// apply again at its first boundary.
    again: Vec<Record>,
    record: BufWriter<std::fs::File>,
    record_path: PathBuf,
    recorded: u64,
    pacer: Pacer,
    paused: bool,
    /// `--duration` given: the live run ends there; otherwise only a person
    /// ends it.
    bounded: bool,
    last_state: Option<Instant>,
    frame_interval: f64,
    /// A state goes out at most this often (`protocol::MAX_STATES_PER_SECOND`).
    state_every: Duration,
    pub url: String,
}

impl LiveDriver {
    /// Starts the server on `addr` and opens `OUT/inputs.jsonl`. `token`:
    /// required on every request (bound beyond loopback). `resumed_at`: the
    /// step of the checkpoint a resumed live run continues from; the inputs
    /// the file holds from before it are kept (and the hands they left
    /// holding taken up), so that the file replays the whole live run.
    pub fn start(
        scene: &Scene,
        out_dir: &Path,
        addr: SocketAddr,
        token: Option<String>,
        bounded: bool,
        resumed_at: Option<u64>,
    ) -> Result<LiveDriver, String> {
        std::fs::create_dir_all(out_dir)
            .map_err(|e| format!("cannot create {}: {e}", out_dir.display()))?;
        let record_path = out_dir.join(inputs::FILE_NAME);
        // Those of the checkpoint's own step are applied again at the first
        // boundary, as a replay of the whole file applies them there.
        let earlier: Vec<Record> = match resumed_at {
            Some(step) if record_path.is_file() => inputs::read(&record_path, scene)?
                .records
                .into_iter()
                .filter(|r| r.step <= step)
                .collect(),
            _ => Vec::new(),
        };
        let mut record = std::fs::File::create(&record_path)
            .map(BufWriter::new)
            .map_err(|e| format!("cannot create {}: {e}", record_path.display()))?;
        let mut hands = Hands::new(scene);
        let mut again = Vec::new();
        for r in &earlier {
            writeln!(record, "{}", r.line())
                .map_err(|e| format!("{}: {e}", record_path.display()))?;
            if Some(r.step) == resumed_at {
                again.push(r.clone());
            } else {
                hands.restore(r);
            }
        }
        let (input_tx, input_rx) = mpsc::channel();
        let (state_tx, state_rx) = watch::channel::<Arc<str>>(Arc::from(""));
        let scene_message: Arc<str> = super::scene_message(scene).into();
        let shared = Arc::new(Shared::new(
            super::page::html(&scene.name),
            scene_message,
            SceneFacts::new(scene),
            state_rx,
            input_tx,
            token.clone(),
        ));
        let server = server::start_live(addr, Arc::clone(&shared))
            .map_err(|e| format!("cannot listen on {addr}: {e}"))?;
        // Bound to every address: the URL names this host, as the lab's
        // other PCs reach it.
        let shown = if server.addr.ip().is_unspecified() {
            format!("{}:{}", rigidsim::cluster::hostname(), server.addr.port())
        } else {
            server.addr.to_string()
        };
        let url = match &token {
            None => format!("http://{shown}/"),
            Some(t) => format!("http://{shown}/?token={t}"),
        };
        let frame_interval = scene.settings.frame_interval;
        Ok(LiveDriver {
            inputs: input_rx,
            states: Some(state_tx),
            shared,
            server: Some(server),
            hands,
            again,
            record,
            record_path,
            recorded: earlier.len() as u64,
            pacer: Pacer::new(0.0, frame_interval),
            paused: false,
            bounded,
            last_state: None,
            frame_interval,
            state_every: Duration::from_secs_f64(1.0 / protocol::MAX_STATES_PER_SECOND),
            url,
        })
    }

    fn io(&self, e: std::io::Error) -> RunError {
        RunError::Io(format!("{}: {e}", self.record_path.display()))
    }

    /// Takes one input at this boundary; `Some(reason)` ends the live run.
    fn take(
        &mut self,
        world: &mut World,
        hand: u32,
        input: Input,
    ) -> Result<Option<&'static str>, RunError> {
        let step = world.state.steps;
        let mut end = None;
        let mut local = None;
        match &input {
            Input::Pause => self.paused = true,
            Input::Resume => {
                if self.paused {
                    self.paused = false;
                    self.pacer.resume(world.time());
                }
            }
            Input::Stop => end = Some("stopped"),
            input => local = self.hands.apply(world, hand, input),
        }
        let reset = input == Input::Reset;
        let line = Record {
            step,
            hand,
            input,
            local,
        }
        .line();
        writeln!(self.record, "{line}").map_err(|e| self.io(e))?;
        self.recorded += 1;
        if reset {
            self.publish(world, true);
        }
        Ok(end)
    }

    /// Sends the state (when one is due, or `now`), and keeps the input
    /// checks' idea of where the bodies are current.
    fn publish(&mut self, world: &World, now: bool) {
        let due = self
            .last_state
            .is_none_or(|at| at.elapsed() >= self.state_every);
        if !(now || due) {
            return;
        }
        self.last_state = Some(Instant::now());
        let bodies: Vec<[f32; 7]> = world
            .state
            .bodies
            .iter()
            .map(|b| {
                let (p, q) = (b.state.position, b.state.orientation);
                [p.x, p.y, p.z, q.w, q.i, q.j, q.k].map(|x| x as f32)
            })
            .collect();
        let with = |a: Activity| {
            world
                .state
                .bodies
                .iter()
                .enumerate()
                .filter(|(_, b)| b.is_dynamic() && b.activity == a)
                .map(|(i, _)| i as u32)
                .collect()
        };
        let state = State {
            kind: "state",
            t: world.time(),
            step: world.state.steps,
            bodies: &bodies,
            resting: with(Activity::Sleeping),
            fallen: with(Activity::Fallen),
            paused: self.paused,
            realtime_factor: if self.paused {
                0.0
            } else {
                self.pacer.realtime_factor()
            },
            worst_frame_s: self.pacer.worst_frame_s(),
            frame_interval_s: self.frame_interval,
            behind_s: self.pacer.behind_s(),
            inputs: self.recorded,
        };
        let text = serde_json::to_string(&state).expect("a state serialises");
        if let Some(tx) = &self.states {
            tx.send_replace(text.into());
        }
        let mut facts = self.shared.facts.lock().unwrap();
        for (f, b) in facts.bodies.iter_mut().zip(&world.state.bodies) {
            f.centre = b.state.position;
        }
    }
}

impl Driver for LiveDriver {
    fn total_steps(&self, scene_steps: u64) -> u64 {
        if self.bounded { scene_steps } else { u64::MAX }
    }

    fn ends_at_rest(&self) -> bool {
        false
    }

    fn before_step(
        &mut self,
        world: &mut World,
        exec: &mut dyn Executor,
    ) -> Result<Option<&'static str>, RunError> {
        for r in std::mem::take(&mut self.again) {
            self.hands.apply(world, r.hand, &r.input);
        }
        if world.state.steps == 0 || self.last_state.is_none() {
            self.pacer.resume(world.time());
            self.publish(world, true);
        }
        self.pacer.wait_for(world.time());
        loop {
            while let Ok((hand, input)) = self.inputs.try_recv() {
                if let Some(end) = self.take(world, hand, input)? {
                    return Ok(Some(end));
                }
            }
            if !self.paused {
                break;
            }
            if rigidsim::interrupt::requested().is_some() {
                return Ok(Some("interrupted"));
            }
            self.publish(world, false);
            std::thread::sleep(PAUSED_POLL);
        }
        self.record.flush().map_err(|e| self.io(e))?;
        self.hands.forces_for_next_step(world, exec);
        Ok(None)
    }

    fn after_step(&mut self, world: &mut World) {
        self.hands.after_step(world);
        self.pacer.stepped(world.time());
        self.publish(world, false);
    }

    fn finish(&mut self, world: &World, end_reason: &str) -> Result<Vec<String>, RunError> {
        writeln!(
            self.record,
            "{}",
            inputs::end_line(world.state.steps, end_reason)
        )
        .and_then(|()| self.record.flush())
        .map_err(|e| self.io(e))?;
        self.publish(world, true);
        if let Some(tx) = self.states.take() {
            tx.send_replace(protocol::end_message(end_reason).into());
        }
        if let Some(server) = self.server.take() {
            server.stop();
        }
        Ok(vec![format!(
            "live run: {} inputs in {}; {:.3} s behind the wall clock in all",
            self.recorded,
            self.record_path.display(),
            self.pacer.behind_total_s
        )])
    }
}
