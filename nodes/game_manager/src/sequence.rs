//! Draws the emotion sequences the robot says: 3, 5 or 7 words from happy, disgusted, sad,
//! angry, uniformly, with no run of one emotion longer than a limit (the authors: no three
//! identical in a row). Each session gets its own ChaCha8 stream from the seed and session id.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sequence_game::{Emotion, Level};

/// The random generators of one session: sequences and line choices on separate streams, so
/// the sequences of a session do not depend on how much feedback the policy chose.
#[derive(Debug, Clone)]
pub struct SessionRng {
    sequences: ChaCha8Rng,
    lines: ChaCha8Rng,
}

impl SessionRng {
    pub fn new(seed: i64, session_id: &str) -> Self {
        let stream = sequence_game::stable_id_hash(session_id);
        let mut sequences = ChaCha8Rng::seed_from_u64(seed as u64);
        sequences.set_stream(stream);
        // The line stream differs from every sequence stream in its seed.
        let mut lines = ChaCha8Rng::seed_from_u64((seed as u64) ^ 0x6c69_6e65_7321_0001);
        lines.set_stream(stream);
        SessionRng { sequences, lines }
    }

    /// A sequence for `level` with runs of at most `max_run` identical emotions.
    pub fn sequence(&mut self, level: Level, max_run: usize) -> Vec<Emotion> {
        draw_sequence(&mut self.sequences, level.sequence_length(), max_run)
    }

    /// Index of the line to say among `count` lines.
    pub fn line(&mut self, count: usize) -> usize {
        if count <= 1 {
            0
        } else {
            self.lines.random_range(0..count)
        }
    }
}

/// `length` emotions, each uniform over those that do not extend a run past `max_run`.
pub fn draw_sequence(rng: &mut ChaCha8Rng, length: usize, max_run: usize) -> Vec<Emotion> {
    let max_run = max_run.max(1);
    let mut out: Vec<Emotion> = Vec::with_capacity(length);
    for _ in 0..length {
        let run_emotion = out.last().copied().filter(|last| {
            out.len() >= max_run && out[out.len() - max_run..].iter().all(|e| e == last)
        });
        let allowed: Vec<Emotion> = Emotion::ALL
            .into_iter()
            .filter(|e| Some(*e) != run_emotion)
            .collect();
        out.push(allowed[rng.random_range(0..allowed.len())]);
    }
    out
}

/// Length of the longest run of one emotion.
pub fn longest_run(sequence: &[Emotion]) -> usize {
    let mut best = 0;
    let mut run = 0;
    for (i, e) in sequence.iter().enumerate() {
        run = if i > 0 && sequence[i - 1] == *e {
            run + 1
        } else {
            1
        };
        best = best.max(run);
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequences_have_the_level_length_and_no_long_runs() {
        let mut rng = SessionRng::new(7, "s1");
        let mut counts = [0usize; 4];
        for i in 0..3000 {
            let level = Level::ALL[i % 3];
            let s = rng.sequence(level, 2);
            assert_eq!(s.len(), level.sequence_length());
            assert!(longest_run(&s) <= 2, "{s:?}");
            for e in s {
                counts[Emotion::ALL.iter().position(|x| *x == e).unwrap_or(0)] += 1;
            }
        }
        // Every emotion appears about a quarter of the time (15,000 draws).
        let total: usize = counts.iter().sum();
        for c in counts {
            let share = c as f64 / total as f64;
            assert!((0.23..0.27).contains(&share), "{counts:?}");
        }
    }

    #[test]
    fn runs_of_two_occur_when_allowed_and_never_with_limit_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let runs: Vec<usize> = (0..500)
            .map(|_| longest_run(&draw_sequence(&mut rng, 7, 2)))
            .collect();
        assert!(runs.contains(&2));
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        assert!((0..500).all(|_| longest_run(&draw_sequence(&mut rng, 7, 1)) == 1));
    }

    #[test]
    fn same_seed_and_session_give_the_same_sequences_others_differ() {
        let draw = |seed, id: &str| {
            let mut r = SessionRng::new(seed, id);
            (0..10)
                .map(|_| r.sequence(Level::THREE, 2))
                .collect::<Vec<_>>()
        };
        assert_eq!(draw(42, "a"), draw(42, "a"));
        assert_ne!(draw(42, "a"), draw(42, "b"));
        assert_ne!(draw(42, "a"), draw(43, "a"));
        // Drawing lines does not move the sequence stream.
        let mut r = SessionRng::new(42, "a");
        let _ = r.line(2);
        assert_eq!(r.sequence(Level::THREE, 2), draw(42, "a")[0]);
    }
}
