//! `rigidsim run SCENE --inputs FILE`: a recorded live run's inputs applied
//! at the steps it took them (`inputs::Hands`, as the live run did), so the
//! run ends on the live run's state hash, on any number of ranks. It never
//! ends by coming to rest (the live run did not); it ends at the recorded
//! last step, or at `--duration` when given. Resumed from a checkpoint, it
//! takes up the hands the earlier inputs left holding and applies the
//! inputs from the checkpoint's step on (those of that very step again: a
//! checkpoint is the state before its boundary's inputs, or, where a live
//! run stopped there, a state they leave as it is when applied again).

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
    applied: usize,
    /// Grabs before a resumed run's first step that could not be taken up.
    unheld: usize,
}

impl Replay {
    pub fn new(scene: &Scene, recording: Recording, bounded: bool) -> Replay {
        Replay {
            recording,
            next: 0,
            hands: Hands::new(scene),
            bounded,
            applied: 0,
            unheld: 0,
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
        // checkpoint) acted in the run it continues: only the hands they
        // left holding are taken up.
        while self.next < records.len() && records[self.next].step < world.state.steps {
            if !self.hands.restore(&records[self.next]) {
                self.unheld += 1;
            }
            self.next += 1;
        }
        while self.next < records.len() && records[self.next].step == world.state.steps {
            let r = &records[self.next];
            self.hands.apply(world, r.hand, &r.input);
            self.next += 1;
            self.applied += 1;
        }
        self.hands.forces_for_next_step(world, exec);
        Ok(None)
    }

    /// The live run took the inputs of its last boundary before it ended
    /// (a reset before a stop acted on the state it ended with).
    fn at_end(&mut self, world: &mut World) {
        let records = &self.recording.records;
        while self.next < records.len() && records[self.next].step == world.state.steps {
            let r = &records[self.next];
            self.hands.apply(world, r.hand, &r.input);
            self.next += 1;
            self.applied += 1;
        }
    }

    fn after_step(&mut self, world: &mut World) {
        self.hands.after_step(world);
    }

    fn finish(&mut self, _world: &World, _end_reason: &str) -> Result<Vec<String>, RunError> {
        let mut notes = vec![format!(
            "applied {} of the {} recorded inputs",
            self.applied,
            self.recording.records.len()
        )];
        if self.unheld > 0 {
            notes.push(format!(
                "{} grabs before the checkpoint have no \"local\" point: those bodies are not held",
                self.unheld
            ));
        }
        Ok(notes)
    }
}
