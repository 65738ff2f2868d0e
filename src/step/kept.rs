//! Answers kept for a split group's parts (`Region::keep_answers`). A part
//! that met another steps again, merged, from the step's start, and takes
//! its events before they met once more: the same island solves, times of
//! impact and pair tests, asked with the same bytes. Each of those is a
//! function of its question alone, so an answer is kept on the thread that
//! found it, keyed by the question's bytes, and given again for the same
//! bytes: only the time changes, never an answer (a question asked on
//! another rank is answered anew there).

use serde::Serialize;
use std::collections::HashMap;

/// Bytes of questions and answers one memo keeps on a thread before it
/// drops them all.
const KEPT_BYTES: usize = 64 << 20;

/// Answers by their question's bytes.
pub(crate) struct Kept<V> {
    answers: HashMap<Vec<u8>, V, rustc_hash::FxBuildHasher>,
    bytes: usize,
}

impl<V> Default for Kept<V> {
    fn default() -> Self {
        Kept {
            answers: HashMap::default(),
            bytes: 0,
        }
    }
}

impl<V: Clone> Kept<V> {
    pub fn get(&self, question: &[u8]) -> Option<V> {
        self.answers.get(question).cloned()
    }

    /// Keeps `answer` (about `answer_bytes` large) for `question`.
    pub fn keep(&mut self, question: Vec<u8>, answer: V, answer_bytes: usize) {
        let bytes = question.len() + answer_bytes;
        if self.bytes + bytes > KEPT_BYTES {
            self.answers.clear();
            self.bytes = 0;
        }
        self.bytes += bytes;
        self.answers.insert(question, answer);
    }
}

/// A question's bytes (bincode's standard configuration).
pub(crate) fn question(q: &impl Serialize) -> Vec<u8> {
    bincode::serde::encode_to_vec(q, bincode::config::standard()).expect("a question encodes")
}

/// Answers `question` from `kept` if it holds it, else by `ask`, keeping
/// that answer (about `answer_bytes` large).
pub(crate) fn one_again_or_anew<V: Clone>(
    kept: &'static std::thread::LocalKey<std::cell::RefCell<Kept<V>>>,
    question: Vec<u8>,
    ask: impl FnOnce() -> V,
    answer_bytes: usize,
) -> V {
    if let Some(answer) = kept.with(|kept| kept.borrow().get(&question)) {
        return answer;
    }
    let answer = ask();
    kept.with(|kept| {
        kept.borrow_mut()
            .keep(question, answer.clone(), answer_bytes)
    });
    answer
}

/// Answers `questions` from `kept` where it holds them and by `ask` for the
/// rest (in their order, in one call), keeping those: `None` questions are
/// never kept. `size` estimates an answer's bytes.
pub(crate) fn again_or_anew<T, V: Clone>(
    kept: &'static std::thread::LocalKey<std::cell::RefCell<Kept<V>>>,
    tasks: Vec<T>,
    questions: Vec<Option<Vec<u8>>>,
    ask: impl FnOnce(Vec<T>) -> Vec<V>,
    size: impl Fn(&V) -> usize,
) -> Vec<V> {
    let mut answers: Vec<Option<V>> = kept.with(|kept| {
        let kept = kept.borrow();
        questions
            .iter()
            .map(|q| q.as_ref().and_then(|q| kept.get(q)))
            .collect()
    });
    let missing: Vec<usize> = (0..tasks.len()).filter(|&i| answers[i].is_none()).collect();
    if !missing.is_empty() {
        let mut tasks: Vec<Option<T>> = tasks.into_iter().map(Some).collect();
        let asked = ask(missing
            .iter()
            .map(|&i| tasks[i].take().expect("asked once"))
            .collect());
        kept.with(|kept| {
            let mut kept = kept.borrow_mut();
            for (&i, a) in missing.iter().zip(&asked) {
                if let Some(q) = &questions[i] {
                    kept.keep(q.clone(), a.clone(), size(a));
                }
            }
        });
        for (i, a) in missing.into_iter().zip(asked) {
            answers[i] = Some(a);
        }
    }
    answers
        .into_iter()
        .map(|a| a.expect("every question answered"))
        .collect()
}
