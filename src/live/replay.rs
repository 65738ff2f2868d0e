//! `rigidsim run SCENE --inputs FILE`: a recorded live run's inputs applied
//! at the steps it took them (`inputs::Hands`, as the live run did), so the
//! run ends on the live run's state hash, on any number of ranks. It never
//! ends by coming to rest (the live run did not); it ends at the recorded
//! last step, or at `--duration` when given. Resumed from a checkpoint, it
//! applies the inputs from the checkpoint's step on.

use super::inputs::{Hands, Recording};
use rigidsim::run::{Driver, RunError};
use rigidsim::scene::Scene;
use rigidsim::step::{Executor, World};

pub struct Replay {
    recording: Recording,
    next: usize,
    hands: Hands,
    /// `--duration` given: it, not the recording, says where the run ends.
    bounded: bool,
}

impl Replay {
    pub fn new(scene: &Scene, recording: Recording, bounded: bool) -> Replay {
        Replay {
            recording,
            next: 0,
            hands: Hands::new(scene),
            bounded,
        }
    }
}

impl Driver for Replay {
    fn total_steps(&self, scene_steps: u64) -> u64 {
        if self.bounded {
            scene_steps
        } else {
            self.recording.last_step
        }
    }

    fn ends_at_rest(&self) -> bool {
        false
    }

    fn before_step(
        &mut self,
        world: &mut World,
        exec: &mut dyn Executor,
    ) -> Result<Option<&'static str>, RunError> {
        let records = &self.recording.records;
        // Inputs before the first boundary this run sees (a resumed run's
        // checkpoint) were the run it continues'.
        while self.next < records.len() && records[self.next].step < world.steps {
            self.next += 1;
        }
        while self.next < records.len() && records[self.next].step == world.steps {
            let r = &records[self.next];
            self.hands.apply(world, r.hand, &r.input);
            self.next += 1;
        }
        self.hands.forces_for_next_step(world, exec);
        Ok(None)
    }

    fn finish(&mut self, _world: &World, _end_reason: &str) -> Result<Vec<String>, RunError> {
        Ok(vec![format!(
            "replayed {} of {} recorded inputs",
            self.next,
            self.recording.records.len()
        )])
    }
}
