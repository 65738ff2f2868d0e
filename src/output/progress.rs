//! Progress on rank 0, on stderr: a bar on a terminal, plain lines otherwise
//! (every 10 % of simulated time), nothing with `--no-progress`.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;

pub struct Progress {
    bar: Option<ProgressBar>,
    plain: bool,
    end: f64,
    next_plain: f64,
}

impl Progress {
    pub fn new(enabled: bool, end_time: f64, label: &str) -> Progress {
        let terminal = std::io::stderr().is_terminal();
        let bar = (enabled && terminal).then(|| {
            let bar = ProgressBar::new(1000);
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix} [{bar:40}] {msg} ({elapsed} elapsed, eta {eta})",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            bar.set_prefix(label.to_string());
            bar
        });
        Progress {
            bar,
            plain: enabled && !terminal,
            end: end_time,
            next_plain: 0.0,
        }
    }

    pub fn update(&mut self, time: f64, awake: usize, total: usize) {
        let fraction = if self.end > 0.0 {
            (time / self.end).clamp(0.0, 1.0)
        } else {
            1.0
        };
        if let Some(bar) = &self.bar {
            bar.set_position((fraction * 1000.0) as u64);
            bar.set_message(format!("t = {time:.3} s, {awake}/{total} bodies moving"));
        } else if self.plain && fraction >= self.next_plain {
            eprintln!(
                "progress: t = {time:.3} s ({:.0} %), {awake}/{total} bodies moving",
                fraction * 100.0
            );
            self.next_plain = (fraction * 10.0).floor() / 10.0 + 0.1;
        }
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
