//! Ctrl-C keeps the work. SIGINT or SIGTERM on a run (or a live run)
//! does not end the process: it raises a flag that the frame loop reads at
//! each step boundary, so the step under way finishes, the trajectory gets
//! its end row, and `summary.json` (`end_reason = "interrupted"`) and a
//! checkpoint are written; the process then exits with the shell's status
//! for the signal, 128 + its number (130 for SIGINT, 143 for SIGTERM). A
//! second signal ends the process at once, with that same status.
//!
//! Under `mpirun` every rank takes the signal (Open MPI's `mpirun` passes a
//! Ctrl-C on to every rank as SIGTERM): the workers and the render rank
//! note it and keep answering rank 0 until it ends the run as usual, so
//! rank 0 can still gather what it needs and write the outputs. `mpirun`
//! kills the ranks `odls_base_sigkill_timeout` seconds (1 by default) after
//! it passed the signal on; `docs/live.md` says how to give a large scene
//! longer.

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// The signal taken, 0 while none was.
struct Flags {
    taken: Arc<AtomicBool>,
    signal: Arc<AtomicUsize>,
}

static FLAGS: OnceLock<Flags> = OnceLock::new();

/// Takes SIGINT and SIGTERM from now on (once per process; later calls do
/// nothing).
pub fn install() -> std::io::Result<()> {
    if FLAGS.get().is_some() {
        return Ok(());
    }
    let flags = Flags {
        taken: Arc::new(AtomicBool::new(false)),
        signal: Arc::new(AtomicUsize::new(0)),
    };
    use signal_hook::consts::{SIGINT, SIGTERM};
    for sig in [SIGINT, SIGTERM] {
        // Handlers run in the order registered: the shutdown sees the flag
        // as the earlier signal left it, so only a second signal ends the
        // process.
        signal_hook::flag::register_conditional_shutdown(
            sig,
            exit_status(sig),
            Arc::clone(&flags.taken),
        )?;
        signal_hook::flag::register_usize(sig, Arc::clone(&flags.signal), sig as usize)?;
        signal_hook::flag::register(sig, Arc::clone(&flags.taken))?;
    }
    let _ = FLAGS.set(flags);
    Ok(())
}

/// The signal taken (SIGINT or SIGTERM), if one was.
pub fn requested() -> Option<i32> {
    let flags = FLAGS.get()?;
    if !flags.taken.load(Ordering::SeqCst) {
        return None;
    }
    match flags.signal.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s as i32),
    }
}

/// The status a process ended by `signal` reports to a shell: 128 + its number.
pub fn exit_status(signal: i32) -> i32 {
    128 + signal
}
