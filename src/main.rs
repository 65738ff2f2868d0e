//! `rigidsim [run] SCENE.toml [options]`, alone or under `mpirun -np N`,
//! `rigidsim live SCENE.toml [--port P] [--bind ADDR] [options]`, alike,
//! `rigidsim export SCENE.toml --to FILE` and
//! `rigidsim view SCENE.toml OUT_DIR [--serve PORT]`.
//!
//! Each subcommand is one function below; only `run` and `live` start MPI,
//! so the others work without mpirun. `rigidsim SCENE …` (no subcommand) is
//! `rigidsim run SCENE …`, the form every script used before subcommands.
//!
//! Exit status: 0 done, 2 bad input (scene, mesh, options, a refused
//! `--resume` checkpoint, an output folder `view` refuses), 3 the run went
//! numerically wrong (outputs written so far and the last checkpoint are
//! kept), 130 or 143 ended by SIGINT or SIGTERM (outputs and a checkpoint
//! written, `rigidsim::interrupt`), 1 anything else.

mod live;
mod view;

use clap::{Args, Parser, Subcommand};
use live::driver::LiveDriver;
use live::inputs::Recording;
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::Root;
use rigidsim::cluster::predict::{LinkModel, Prediction};
use rigidsim::cluster::{self, MpiExecutor, RemoteFrames, Roles};
use rigidsim::output::checkpoint::Checkpoint;
use rigidsim::output::summary::RankHost;
use rigidsim::output::trajectory;
use rigidsim::render::{FrameRenderer, FrameSink, InlineFrames, NoFrames};
use rigidsim::run::{self, Driver, RunError, RunOptions, Unattended};
use rigidsim::scene::Scene;
use rigidsim::step::{Executor, Inline};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The step allocates many small vectors; see Cargo.toml.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[derive(Parser, Debug)]
#[command(
    version,
    about = "Rigid-body dynamics over an MPI cluster of lab PCs",
    // `rigidsim SCENE [options]` is `rigidsim run SCENE [options]`.
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    run: Option<RunArgs>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Simulate a scene, alone or under mpirun (the default command).
    Run(RunArgs),
    /// Simulate a scene at the pace of the wall clock, seen and pushed from a browser.
    ///
    /// Alone or under mpirun; the page at http://ADDR:PORT/, its WebSocket
    /// at /ws (docs/live.md). Ends on Ctrl-C, --duration, or a stop from the
    /// page, with the outputs of `run` and OUT/inputs.jsonl.
    Live(LiveArgs),
    /// Write a scene's bodies, exactly as rigidsim simulates them, as JSON (no MPI).
    Export(ExportArgs),
    /// Write OUT_DIR/replay.html, a replay of a finished run of the scene for
    /// any browser (one self-contained file; no MPI).
    View(ViewArgs),
}

/// `LinkModel::LAB_100_MBIT`'s latency in the unit of `--link-latency-us`.
const LAB_LATENCY_US: f64 = 550.0;

#[derive(Args, Debug)]
struct RunArgs {
    /// Scene file (TOML).
    scene: PathBuf,
    /// Output folder (default out/<scene name>/).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Simulated seconds to run (overrides world.duration).
    #[arg(long)]
    duration: Option<f64>,
    /// Base time step in seconds (overrides world.dt).
    #[arg(long)]
    dt: Option<f64>,
    /// Trajectory sampling interval in simulated seconds.
    #[arg(long)]
    sample_every: Option<f64>,
    /// The contact model's dial (m/s): approaches inside a pile up to this
    /// speed, and any below g·dt/2, are solved at the step by speculative
    /// contacts; 0: every impact an exact event (overrides
    /// world.speculative_speed; default 0).
    #[arg(long)]
    speculative_speed: Option<f64>,
    /// Blocks a large contact island is cut into so that the ranks share
    /// its sweeps, with the same results on any rank count (overrides
    /// world.island_blocks; default 1: each island swept whole).
    #[arg(long)]
    island_blocks: Option<u32>,
    /// Do not render, even if the scene has a [render] section.
    #[arg(long)]
    no_render: bool,
    /// No progress bar or progress lines.
    #[arg(long)]
    no_progress: bool,
    /// Never put resting systems to sleep (costs time; for measurements).
    #[arg(long)]
    no_sleep: bool,
    /// Split every large interaction group into the parts that meet within
    /// a step, checked against each other and merged where their paths
    /// meet, on any number of ranks (by default only on several ranks, a
    /// group that would hold up the others; docs/architecture.md).
    #[arg(long, conflicts_with = "whole_groups")]
    split_groups: bool,
    /// Never split an interaction group, not even one that holds up the
    /// other ranks (for measurements; the results are the same).
    #[arg(long)]
    whole_groups: bool,
    /// Test aid: make rank R take F times longer per task, e.g. --slow-rank 2=3.0.
    #[arg(long, value_parser = parse_slow)]
    slow_rank: Vec<(i32, f64)>,
    /// Test aid: write every contact island of --capture-min-rows rows or
    /// more to DIR, one file each (the solver's fixtures and benchmark).
    #[arg(long, value_name = "DIR")]
    capture_islands: Option<PathBuf>,
    /// Smallest island (LCP rows) --capture-islands writes.
    #[arg(long, value_name = "ROWS", default_value_t = 60)]
    capture_min_rows: usize,
    /// Distribute every stage whatever its size (tests of determinism and balance).
    #[arg(long)]
    force_distribute: bool,
    /// On one rank: time each task of the stages other ranks could take and
    /// predict the whole step on 2, 4, 8 and 16 ranks over the link below
    /// (summary.json's `distributed.predicted`); on any number, time the
    /// group steps' event loops (`distributed.event_shared_bound`). Costs
    /// 5-10 % of the run (each task's messages encoded and decoded once more).
    #[arg(long)]
    predict: bool,
    /// The link --predict assumes: one-way latency in microseconds (default
    /// half the 1.1 ms round trip of a lab's 100 Mbit/s network).
    #[arg(long, value_name = "US", default_value_t = LAB_LATENCY_US)]
    link_latency_us: f64,
    /// The link's rate in bytes per second (default the 7.7 MB/s of MPI
    /// payload a lab's 100 Mbit/s network carries).
    #[arg(long, value_name = "B", default_value_t = LinkModel::LAB_100_MBIT.bytes_per_s)]
    link_bytes_per_s: f64,
    /// Write the full simulation state to OUT/checkpoint.bin every S
    /// simulated seconds and at the end (atomically: a crash keeps the last one).
    #[arg(long, value_name = "S")]
    checkpoint_every: Option<f64>,
    /// Continue from a checkpoint (same scene file and --dt; any rank count).
    /// The trajectory in the output folder, if any, continues from its time.
    #[arg(long, value_name = "FILE")]
    resume: Option<PathBuf>,
    /// Apply a live run's inputs (its OUT/inputs.jsonl) at the steps it
    /// took them: the run ends on the live run's state, at its last step (or
    /// at --duration), never by coming to rest.
    #[arg(long, value_name = "FILE")]
    inputs: Option<PathBuf>,
}

#[derive(Args, Debug)]
struct LiveArgs {
    #[command(flatten)]
    run: RunArgs,
    /// Port of the page and its WebSocket (0: any free port; the URL is
    /// printed either way).
    #[arg(long, default_value_t = 8080)]
    port: u16,
    /// Address to listen on. Beyond loopback, every request must carry the
    /// random token of the printed URL.
    #[arg(long, default_value = "127.0.0.1")]
    bind: std::net::IpAddr,
}

#[derive(Args, Debug)]
struct ExportArgs {
    /// Scene file (TOML).
    scene: PathBuf,
    /// JSON file to write (format in README.md, "rigidsim export").
    #[arg(long, value_name = "FILE")]
    to: PathBuf,
}

#[derive(Args, Debug)]
struct ViewArgs {
    /// Scene file (TOML) the run was made from.
    scene: PathBuf,
    /// The run's output folder (the one `rigidsim SCENE --out` wrote).
    out_dir: PathBuf,
    /// Then serve the page on 127.0.0.1:PORT (0: any free port) until stopped,
    /// for a browser on another machine through ssh port forwarding.
    #[arg(long, value_name = "PORT")]
    serve: Option<u16>,
}

fn parse_slow(s: &str) -> Result<(i32, f64), String> {
    let (r, f) = s
        .split_once('=')
        .ok_or("expected RANK=FACTOR, e.g. 2=3.0")?;
    let r: i32 = r.trim().parse().map_err(|_| format!("bad rank '{r}'"))?;
    let f: f64 = f.trim().parse().map_err(|_| format!("bad factor '{f}'"))?;
    if r < 0 || !f.is_finite() || f < 1.0 {
        return Err("rank must be ≥ 0 and factor ≥ 1".into());
    }
    Ok((r, f))
}

fn main() -> ExitCode {
    no_transparent_huge_pages();
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    match (cli.command, cli.run) {
        (Some(Command::Run(args)), _) | (None, Some(args)) => run_scene(args, None),
        (Some(Command::Live(args)), _) => {
            if args.run.inputs.is_some() {
                eprintln!(
                    "rigidsim: error: --inputs replays a live run: rigidsim run SCENE --inputs FILE"
                );
                return ExitCode::from(2);
            }
            let live = LiveServer {
                addr: std::net::SocketAddr::new(args.bind, args.port),
            };
            run_scene(args.run, Some(live))
        }
        (Some(Command::Export(args)), _) => export_scene(args),
        (Some(Command::View(args)), _) => view_run(args),
        (None, None) => {
            use clap::CommandFactory;
            let e = Cli::command().error(
                clap::error::ErrorKind::MissingRequiredArgument,
                "a scene file is required: rigidsim [run] SCENE.toml [options]",
            );
            let _ = e.print();
            ExitCode::from(2)
        }
    }
}

/// Turns transparent huge pages off for this process (what mimalloc's
/// `MIMALLOC_ALLOW_THP=0` does), before the step allocates. mimalloc asks
/// for huge pages on its arenas and returns freed pages to the system
/// after a delay; each later touch of such memory then had the kernel zero
/// a whole 2 MiB page: 6-10 % of a pour's samples were `clear_page_erms`
/// under a page fault from `mi_page_fresh_alloc`, on every rank
/// (`docs/benchmarks.md`, *Allocation*). With 4 KiB pages only what is
/// touched is zeroed. A kernel without the switch keeps its default.
fn no_transparent_huge_pages() {
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_THP_DISABLE takes no pointers; it sets a flag of this
    // process's memory map, read by the kernel at each page fault. prctl is
    // variadic and the kernel reads its arguments as unsigned longs (and
    // refuses the call unless the last three are 0), so they are passed at
    // that width.
    unsafe {
        let (on, unused): (libc::c_ulong, libc::c_ulong) = (1, 0);
        libc::prctl(libc::PR_SET_THP_DISABLE, on, unused, unused, unused);
    }
}

/// `rigidsim export`: loads the scene as `run` does (same one-line error,
/// exit 2) and writes its JSON; never starts MPI.
fn export_scene(args: ExportArgs) -> ExitCode {
    let scene = match rigidsim::scene::load(&args.scene) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("rigidsim: error: {e}");
            return ExitCode::from(2);
        }
    };
    if let Err(e) = rigidsim::export::write(&scene, &args.to) {
        eprintln!("rigidsim: error: cannot write {}: {e}", args.to.display());
        return ExitCode::from(1);
    }
    ExitCode::SUCCESS
}

/// `rigidsim view`: writes the replay and prints its path (then serves it,
/// with `--serve`); a refused folder or scene is one line and exit 2.
fn view_run(args: ViewArgs) -> ExitCode {
    let fail = |e: view::ViewError| {
        eprintln!("rigidsim: error: {e}");
        ExitCode::from(e.exit_code())
    };
    let page = match view::write_replay(&args.scene, &args.out_dir) {
        Ok(p) => p,
        Err(e) => return fail(e),
    };
    println!("{}", page.display());
    match args.serve.map(|port| view::serve(&page, port)) {
        Some(Err(e)) => fail(e),
        _ => ExitCode::SUCCESS,
    }
}

/// Open MPI's start-up choices for this program, each only where the
/// environment does not make it already (`OMPI_MCA_*`): a run paid 0.3 s
/// before its first step, alone or under `mpirun -np 2`, most of it Open
/// MPI trying messaging layers for fast networks (the PSM2 library alone
/// sleeps 0.1 s looking for Omni-Path cards) before settling on `ob1`,
/// which it picks on the lab's Ethernet PCs anyway; without `mpirun` it also
/// started a helper daemon, which a job of one process that never spawns
/// another does not need. With both: 0.02 s alone, 0.12 s under `mpirun
/// -np 2` (`README.md`, *Running on a lab's PCs*). A cluster with InfiniBand can still
/// choose UCX by setting `OMPI_MCA_pml=ucx`.
///
/// Without `mpirun`, the run also gets a temporary folder of its own (see
/// `MpiTempDir`); the returned guard removes it once MPI has finished.
fn open_mpi_defaults() -> Option<MpiTempDir> {
    let launched = ["OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK"]
        .iter()
        .any(|v| std::env::var_os(v).is_some());
    let mut defaults = vec![("OMPI_MCA_pml", "ob1".to_string())];
    let mut temp_dir = None;
    if !launched {
        defaults.push(("OMPI_MCA_ess_singleton_isolated", "1".into()));
        if std::env::var_os(MpiTempDir::SETTING).is_none() {
            temp_dir = MpiTempDir::create();
        }
    }
    if let Some(dir) = &temp_dir {
        defaults.push((MpiTempDir::SETTING, dir.0.display().to_string()));
    }
    for (key, value) in defaults {
        if std::env::var_os(key).is_none() {
            // SAFETY: called before MPI starts and before this program
            // starts any thread, so nothing reads the environment meanwhile.
            unsafe { std::env::set_var(key, value) };
        }
    }
    temp_dir
}

/// A folder of this process's own for Open MPI's temporary files, when it
/// runs without `mpirun`. Alone, Open MPI keeps them under
/// `/tmp/ompi.<host>.<uid>/`, shared by every such process of the user, and
/// one that ends removes that folder while another that starts is making
/// its own inside: "A call to mkdir was unable to create the desired
/// directory: /tmp/ompi.vm.0/jf.0" and exit 1 at `MPI_Init`, 4 of 240 runs
/// of four loops of one-rank runs side by side (and one CI run of the
/// tests, which start several at once).
struct MpiTempDir(std::path::PathBuf);

impl MpiTempDir {
    /// Open MPI's setting for where its temporary folders go.
    const SETTING: &str = "OMPI_MCA_orte_tmpdir_base";

    /// `<temp>/rigidsim-<pid>`, made now; `None` (Open MPI's own choice)
    /// where it cannot be made. First removes those of processes that no
    /// longer run (a run that was killed could not remove its own).
    fn create() -> Option<MpiTempDir> {
        let temp = std::env::temp_dir();
        Self::remove_stale(&temp);
        let dir = temp.join(format!("{}{}", Self::PREFIX, std::process::id()));
        std::fs::create_dir_all(&dir).ok()?;
        Some(MpiTempDir(dir))
    }

    const PREFIX: &str = "rigidsim-";

    fn remove_stale(temp: &std::path::Path) {
        let Ok(entries) = std::fs::read_dir(temp) else {
            return;
        };
        for entry in entries.flatten() {
            let name = entry.file_name();
            let pid = name
                .to_str()
                .and_then(|n| n.strip_prefix(Self::PREFIX))
                .and_then(|pid| pid.parse::<u32>().ok());
            let gone =
                pid.is_some_and(|pid| !std::path::Path::new(&format!("/proc/{pid}")).exists());
            if gone {
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
    }
}

impl Drop for MpiTempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Where `rigidsim live` serves its page and WebSocket.
struct LiveServer {
    addr: std::net::SocketAddr,
}

/// `rigidsim run` (and the short form), and `rigidsim live` (with `live`):
/// every rank of the MPI job, or the only one.
fn run_scene(cli: RunArgs, live: Option<LiveServer>) -> ExitCode {
    // Declared before the universe, so removed after MPI has finalised.
    let _mpi_temp = open_mpi_defaults();
    let Some(universe) = mpi::initialize() else {
        eprintln!("rigidsim: MPI could not be initialised");
        return ExitCode::from(1);
    };
    let world = universe.world();
    let job = Job {
        world: &world,
        rank: world.rank(),
    };
    let rank = job.rank;
    let size = world.size();
    // Every rank takes Ctrl-C and SIGTERM (under mpirun each gets one):
    // rank 0 ends the run at the next step boundary, the others keep
    // answering it until it does (`rigidsim::interrupt`).
    if let Err(e) = rigidsim::interrupt::install() {
        job.say(&format!(
            "warning: Ctrl-C will end the run where it stands: {e}"
        ));
    }

    // Every rank loads the scene itself; they all fail alike on bad input,
    // and only rank 0 says so.
    let opts = run_options(&cli, live.is_some());
    let scene = match load_scene(&cli, &opts, live.is_some()) {
        Ok(s) => s,
        Err(e) => {
            job.say(&format!("error: {e}"));
            return ExitCode::from(2);
        }
    };
    let out_dir = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| run::default_out_dir(&scene));
    let resume = match job.read_resume(&cli, &scene, &opts, &out_dir) {
        Ok(r) => r,
        Err(code) => return code,
    };
    let (recording, live_driver) = match job.start_inputs(
        &cli,
        &scene,
        &opts,
        &out_dir,
        live.as_ref(),
        resume.as_ref(),
    ) {
        Ok(started) => started,
        Err(code) => return code,
    };
    if let Some(dir) = &cli.capture_islands {
        if let Err(e) = rigidsim::output::capture::start(dir.clone(), cli.capture_min_rows, rank) {
            job.say(&format!("error: --capture-islands {}: {e}", dir.display()));
            return ExitCode::from(2);
        }
    }
    let roles = Roles::new(size, scene.settings.render.is_some());
    // Which host each rank runs on (rank 0 only): for messages naming a
    // rank that stops answering, and for `summary.json`.
    let hosts = cluster::rank_hosts(&world);
    if let Some(line) = cluster::hosts_line(&hosts) {
        job.say(&line);
    }
    // And which vector units each rank's CPU has: a lab of mixed PCs is
    // told where its results may depend on the placement.
    let vector_units = cluster::rank_vector_units(&world);
    if let Some(line) = cluster::mixed_vector_units_line(&vector_units) {
        job.say(&line);
    }

    if rank != 0 {
        if Some(rank) == roles.renderer {
            cluster::renderer_loop(&world, &scene, &out_dir);
        } else {
            cluster::worker_loop(&world, &scene, cluster::slow_factor(&cli.slow_rank, rank));
        }
        return interrupted_status().unwrap_or(ExitCode::SUCCESS);
    }
    Coordinator {
        cli,
        scene,
        opts,
        out_dir,
        roles,
        hosts,
        vector_units,
        resume,
        recording,
        live_driver,
    }
    .run(&job)
}

/// The command line's choices that change a run (`live`: a live run).
fn run_options(cli: &RunArgs, live: bool) -> RunOptions {
    RunOptions {
        out_dir: cli.out.clone(),
        duration: cli.duration,
        dt: cli.dt,
        sample_every: cli.sample_every,
        speculative_speed: cli.speculative_speed,
        island_blocks: cli.island_blocks,
        no_render: cli.no_render,
        // A live run prints its address, not a bar.
        no_progress: cli.no_progress || live,
        no_sleep: cli.no_sleep,
        split_groups: cli.split_groups,
        time_events: cli.predict,
        checkpoint_every: cli.checkpoint_every,
    }
}

/// The predicted link's parameters are numbers a link can have.
fn check_link(cli: &RunArgs) -> Result<(), String> {
    let (latency, rate) = (cli.link_latency_us, cli.link_bytes_per_s);
    if !latency.is_finite() || latency < 0.0 {
        return Err(format!(
            "--link-latency-us must be a finite number ≥ 0 (got {latency})"
        ));
    }
    if !rate.is_finite() || rate <= 0.0 {
        return Err(format!(
            "--link-bytes-per-s must be a finite number > 0 (got {rate})"
        ));
    }
    Ok(())
}

/// The scene with the command line's overrides (`live`: a live run).
fn load_scene(cli: &RunArgs, opts: &RunOptions, live: bool) -> Result<Scene, String> {
    let mut scene = rigidsim::scene::load(&cli.scene).map_err(|e| e.to_string())?;
    run::apply_overrides(&mut scene, opts)?;
    check_link(cli)?;
    // A live run may last hours: its trajectory is sampled at the scene's
    // `sample_every` where given, otherwise at the frame interval, not at
    // every step (docs/live.md states what an hour costs on disk).
    if live && scene.settings.sample_every.is_none() {
        scene.settings.sample_every = Some(scene.settings.frame_interval);
    }
    Ok(scene)
}

/// This process in the MPI job (`run_scene`).
struct Job<'w> {
    world: &'w SimpleCommunicator,
    rank: i32,
}

impl Job<'_> {
    /// `rigidsim: MSG` on stderr, from rank 0 only: every rank meets the
    /// same errors, and one says so.
    fn say(&self, msg: &str) {
        if self.rank == 0 {
            eprintln!("rigidsim: {msg}");
        }
    }

    /// Rank 0's `code` told to every rank: an exit status other than 0
    /// ends all ranks alike.
    fn agree(&self, mut code: i32) -> Result<(), ExitCode> {
        self.world.process_at_rank(0).broadcast_into(&mut code);
        if code != 0 {
            return Err(ExitCode::from(code as u8));
        }
        Ok(())
    }

    /// `--resume`: rank 0 reads the checkpoint and checks it against the
    /// scene, then tells every rank whether to go on, so that a refused
    /// checkpoint ends all ranks alike (exit 2) before any work is handed
    /// out. Only rank 0 needs the file.
    fn read_resume(
        &self,
        cli: &RunArgs,
        scene: &Scene,
        opts: &RunOptions,
        out_dir: &Path,
    ) -> Result<Option<Checkpoint>, ExitCode> {
        let Some(path) = &cli.resume else {
            return Ok(None);
        };
        let mut resume = None;
        let mut code: i32 = 0;
        if self.rank == 0 {
            // The trajectory the run will append to must be the one the
            // checkpoint's run wrote (or missing: a new one is started).
            let traj = out_dir.join("trajectory.csv");
            let checked = Checkpoint::read_for(path, scene, !opts.no_sleep)
                .map_err(|e| e.to_string())
                .and_then(|ck| {
                    trajectory::check_resumable(&traj, ck.run.trajectory)
                        .map(|()| ck)
                        .map_err(|e| format!("{}: {e}", traj.display()))
                });
            match checked {
                Ok(ck) => resume = Some(ck),
                Err(e) => {
                    self.say(&format!("error: {e}"));
                    code = 2;
                }
            }
        }
        self.agree(code)?;
        Ok(resume)
    }

    /// `--inputs` and `live`: rank 0 reads the recording or starts the
    /// server, and tells every rank whether to go on (as for `--resume`).
    fn start_inputs(
        &self,
        cli: &RunArgs,
        scene: &Scene,
        opts: &RunOptions,
        out_dir: &Path,
        live: Option<&LiveServer>,
        resume: Option<&Checkpoint>,
    ) -> Result<(Option<Recording>, Option<LiveDriver>), ExitCode> {
        let mut recording = None;
        let mut live_driver = None;
        if cli.inputs.is_some() || live.is_some() {
            let mut code: i32 = 0;
            if self.rank == 0 {
                let started = match (&cli.inputs, live) {
                    (Some(path), _) => live::inputs::read(path, scene)
                        .map(|r| recording = Some(r))
                        .map_err(|e| (e, 2)),
                    (None, Some(l)) => start_live(
                        scene,
                        out_dir,
                        l,
                        opts.duration.is_some(),
                        resume.map(|ck| ck.steps),
                    )
                    .map(|s| live_driver = Some(s))
                    .map_err(|e| (e, 1)),
                    (None, None) => Ok(()),
                };
                if let Err((e, c)) = started {
                    self.say(&format!("error: {e}"));
                    code = c;
                }
            }
            self.agree(code)?;
        }
        Ok((recording, live_driver))
    }
}

/// What rank 0 runs the scene with (`Coordinator::run`).
struct Coordinator {
    cli: RunArgs,
    scene: Scene,
    opts: RunOptions,
    out_dir: PathBuf,
    roles: Roles,
    /// Each rank's host and vector units (by rank).
    hosts: Vec<String>,
    vector_units: Vec<String>,
    resume: Option<Checkpoint>,
    recording: Option<Recording>,
    live_driver: Option<LiveDriver>,
}

/// Where rank 0's frames go (`Coordinator::frames`).
enum Frames<'w> {
    None(NoFrames),
    Remote(RemoteFrames<'w>),
    /// Boxed: the renderer is large beside the others.
    Local(Box<InlineFrames>),
}

impl Frames<'_> {
    fn sink(&mut self) -> &mut dyn FrameSink {
        match self {
            Frames::None(f) => f,
            Frames::Remote(f) => f,
            Frames::Local(f) => f.as_mut(),
        }
    }
}

impl Coordinator {
    /// Rank 0's run: the steps inline or through the workers, the frames
    /// drawn here or by the renderer rank, and the run's outcome told.
    fn run(mut self, job: &Job) -> ExitCode {
        let world = job.world;
        let link = LinkModel {
            latency_s: self.cli.link_latency_us / 1e6,
            bytes_per_s: self.cli.link_bytes_per_s,
        };
        let mut inline = if self.cli.predict {
            Inline::profiled(Box::new(Prediction::new(link)))
        } else {
            Inline::default()
        };
        let mut mpi_exec;
        let mut link_rates = Vec::new();
        let exec: &mut dyn Executor = if self.roles.workers.is_empty() {
            &mut inline
        } else {
            mpi_exec = MpiExecutor::new(world, self.roles.clone(), &self.scene.objects);
            mpi_exec.force_distribute = self.cli.force_distribute;
            mpi_exec.split_where_it_pays = !self.cli.whole_groups;
            mpi_exec.set_hosts(self.hosts.clone());
            link_rates = mpi_exec.link_rates();
            &mut mpi_exec
        };
        let mut frames = match self.frames(job) {
            Ok(f) => f,
            Err(code) => return code,
        };
        let frames = frames.sink();
        let hosts: Vec<RankHost> = std::mem::take(&mut self.hosts)
            .into_iter()
            .enumerate()
            .map(|(r, host)| RankHost {
                host,
                link_bytes_per_s: link_rates.get(r).copied().flatten(),
                vector_units: self.vector_units.get(r).cloned().unwrap_or_default(),
            })
            .collect();
        let mut unattended = Unattended;
        let mut replay;
        let driver: &mut dyn Driver = match (&mut self.live_driver, self.recording.take()) {
            (Some(s), _) => s,
            (None, Some(r)) => {
                replay = live::replay::Replay::new(&self.scene, r, self.opts.duration.is_some());
                &mut replay
            }
            (None, None) => &mut unattended,
        };
        let outcome = run::run_driven(
            self.scene,
            &self.opts,
            &self.out_dir,
            exec,
            &mut *frames,
            self.resume,
            &hosts,
            driver,
        );
        if let Some(why) = frames.lost() {
            // The results are written; a rank that does not answer would hang
            // MPI's finalize, so the job ends here (mpirun names the ranks).
            eprintln!(
                "rigidsim: error: {why}; results in {}; ending the job",
                self.out_dir.display()
            );
            world.abort(6);
        }
        report(outcome, &self.out_dir, world)
    }

    /// Where the frames go: nowhere without a render section, else to the
    /// renderer rank, or drawn here where there is none.
    fn frames<'w>(&self, job: &Job<'w>) -> Result<Frames<'w>, ExitCode> {
        Ok(
            match (self.scene.settings.render.is_some(), self.roles.renderer) {
                (false, _) => Frames::None(NoFrames),
                (true, Some(r)) => {
                    let host = self
                        .hosts
                        .get(r as usize)
                        .cloned()
                        .unwrap_or_else(|| "?".into());
                    Frames::Remote(RemoteFrames::new(job.world, r, host))
                }
                (true, None) => {
                    if let Err(e) = std::fs::create_dir_all(&self.out_dir) {
                        job.say(&format!(
                            "error: cannot create {}: {e}",
                            self.out_dir.display()
                        ));
                        return Err(ExitCode::from(1));
                    }
                    match FrameRenderer::new(&self.scene, &self.out_dir) {
                        Ok(r) => Frames::Local(Box::new(InlineFrames(r))),
                        Err(e) => {
                            job.say(&format!("warning: {e}; continuing without frames"));
                            Frames::None(NoFrames)
                        }
                    }
                }
            },
        )
    }
}

/// The run's outcome told on stderr, and the exit status it gives.
fn report(
    outcome: Result<rigidsim::output::summary::Summary, RunError>,
    out_dir: &Path,
    world: &SimpleCommunicator,
) -> ExitCode {
    match outcome {
        Ok(summary) => {
            eprintln!(
                "rigidsim: {} bodies, {:.3} s simulated in {:.3} s ({:.2}x real time), ended by {}; results in {}",
                summary.bodies,
                summary.sim_time_s,
                summary.wall_time_s,
                summary.realtime_factor,
                summary.end_reason,
                out_dir.display()
            );
            interrupted_status().unwrap_or(ExitCode::SUCCESS)
        }
        Err(RunError::Failed(msg)) => {
            eprintln!(
                "rigidsim: error: {msg}; outputs so far kept in {}",
                out_dir.display()
            );
            ExitCode::from(3)
        }
        Err(RunError::Io(msg)) => {
            eprintln!("rigidsim: error: {msg}");
            world.abort(1);
        }
    }
}

/// 130 after Ctrl-C, 143 after SIGTERM (the shell's status for a process the
/// signal ended), once the run has kept its work; `None` without a signal.
fn interrupted_status() -> Option<ExitCode> {
    rigidsim::interrupt::requested()
        .map(|sig| ExitCode::from(rigidsim::interrupt::exit_status(sig) as u8))
}

/// Starts a live run's server (rank 0) and prints its URL on stdout.
fn start_live(
    scene: &rigidsim::scene::Scene,
    out_dir: &std::path::Path,
    live: &LiveServer,
    bounded: bool,
    resumed_at: Option<u64>,
) -> Result<live::driver::LiveDriver, String> {
    let token = if live.addr.ip().is_loopback() {
        None
    } else {
        Some(live::server::random_token().map_err(|e| format!("no random token: {e}"))?)
    };
    let driver =
        live::driver::LiveDriver::start(scene, out_dir, live.addr, token, bounded, resumed_at)?;
    use std::io::Write;
    println!("{}", driver.url);
    let _ = std::io::stdout().flush();
    eprintln!(
        "rigidsim: live run of {} at {} (Ctrl-C, or stop on the page, ends it; results in {})",
        scene.name,
        driver.url,
        out_dir.display()
    );
    Ok(driver)
}
