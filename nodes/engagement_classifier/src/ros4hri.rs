//! Engagement the ROS4HRI way (REP-155): the face of each camera source is a *person*, and
//! each closed second of it an `hri_msgs/EngagementLevel`. Sans-IO: seconds, game states and
//! times in; what to publish out, in the order to publish it.
//!
//! Every person is *anonymous* (REP-155: detected, not identified, no permanent id): the suite
//! recognises nobody, and the only identity it has, the session's user id, must not reach the
//! ROS graph (docs/privacy.md), so an id is never made from it. A person's id,
//! `anonymous_person_<8 hex digits>` (the prefix ROS4HRI's person manager gives anonymous
//! persons), is a hash of its camera source and the second it was first seen. A person begins
//! with a second that has a face, ends when no face was seen for `ros4hri_tracked_timeout_s`
//! or when a session starts or ends (the child may have changed), and is never reused: a face
//! seen again is a new person, as a face detector gives a face seen again a new id.
//!
//! Per person: `anonymous` (latched `true`, before the lists name the person, so libhri, which
//! subscribes only once it sees the id listed, gets it from the writer's history) and a level
//! per second. The lists `tracked` and `known` (the same ids: the person manager forgets an
//! anonymous person once its face is lost, so no anonymous person is known untracked) go out
//! on every change and at least once a second, since libhri reads them volatile.
//!
//! Levels, with thresholds from parameters: no face in the second, UNKNOWN; smoothed
//! engagement at or above the engaged threshold, ENGAGED; at or below the disengaged one,
//! DISENGAGED; between them, ENGAGING when it rose since the person's last second and
//! DISENGAGING when it fell (REP-155: starting to look towards, or away from, the robot).

use crate::params::EngagementClassifierParams;
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::hri_msgs::{EngagementLevel, IdsList};
use qt_therapy_msgs::std_msgs::{BoolMsg, Header};
use qt_therapy_msgs::{ExpectedEngagement, GameState};
use std::collections::BTreeMap;

/// The prefix of every person id (as `hri_person_manager`'s `kAnonymous`).
pub const ANONYMOUS_PREFIX: &str = "anonymous_person_";

/// The lists go out again after this much message time without a change.
const LIST_REFRESH_NS: i64 = 1_000_000_000;

/// What to publish, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum HriOutput {
    /// A person reported from now on: make its topics and publish `anonymous`
    /// (`/humans/persons/<person>/anonymous`, latched) before the lists name it.
    NewPerson { person: String, anonymous: BoolMsg },
    /// A person's level, for `/humans/persons/<person>/engagement_status`.
    Engagement {
        person: String,
        level: EngagementLevel,
    },
    /// `/humans/persons/tracked`.
    Tracked(IdsList),
    /// `/humans/persons/known`.
    Known(IdsList),
    /// A person no longer reported (the lists above no longer name it): its topics end.
    PersonGone { person: String },
}

#[derive(Debug, Clone)]
struct Person {
    id: String,
    /// End of the last second with a face, ns.
    last_face_ns: i64,
    /// Smoothed engagement of the person's last second (None: no face).
    last_value: Option<f32>,
}

/// The mapping from seconds to ROS4HRI persons and levels.
#[derive(Debug, Clone)]
pub struct PersonEngagement {
    engaged: f64,
    disengaged: f64,
    timeout_ns: i64,
    /// The running session's id (compared, never published), None outside a session.
    session: Option<String>,
    /// A session started or ended since the last second: every person ends.
    session_changed: bool,
    /// Per camera source ("<camera>/<face>"), its person.
    persons: BTreeMap<String, Person>,
    /// The ids last listed, and when (ns); None before the first list.
    listed: Option<(Vec<String>, i64)>,
}

impl PersonEngagement {
    pub fn new(params: &EngagementClassifierParams) -> Self {
        PersonEngagement {
            engaged: params.ros4hri_engaged_threshold,
            disengaged: params.ros4hri_disengaged_threshold,
            timeout_ns: (params.ros4hri_tracked_timeout_s * 1e9) as i64,
            session: None,
            session_changed: false,
            persons: BTreeMap::new(),
            listed: None,
        }
    }

    /// New thresholds (a change while running): levels from the next closed second on.
    pub fn set_thresholds(&mut self, params: &EngagementClassifierParams) {
        self.engaged = params.ros4hri_engaged_threshold;
        self.disengaged = params.ros4hri_disengaged_threshold;
    }

    /// The game's state: a session starting or ending ends every person.
    pub fn on_game_state(&mut self, g: &GameState) {
        let in_session =
            !g.session_id.is_empty() && g.phase != GameState::IDLE && !GameState::is_ended(g.phase);
        let session = in_session.then(|| g.session_id.clone());
        if session != self.session {
            self.session = session;
            self.session_changed = true;
        }
    }

    /// One closed second of one source.
    pub fn on_second(&mut self, e: &ExpectedEngagement) -> Vec<HriOutput> {
        let now = e.window_end.to_nanos();
        let mut out = Vec::new();
        let mut gone: Vec<String> = Vec::new();
        if std::mem::take(&mut self.session_changed) {
            gone.extend(
                std::mem::take(&mut self.persons)
                    .into_values()
                    .map(|p| p.id),
            );
        }
        let timeout = self.timeout_ns;
        self.persons.retain(|_, p| {
            let keep = now - p.last_face_ns <= timeout;
            if !keep {
                gone.push(p.id.clone());
            }
            keep
        });

        let value = e.has_faces.then_some(e.smoothed);
        if !self.persons.contains_key(&e.source) && value.is_some() {
            let id = self.new_id(&e.source, e.window_start.to_nanos());
            out.push(HriOutput::NewPerson {
                person: id.clone(),
                anonymous: BoolMsg { data: true },
            });
            self.persons.insert(
                e.source.clone(),
                Person {
                    id,
                    last_face_ns: now,
                    last_value: None,
                },
            );
        }
        if let Some(p) = self.persons.get_mut(&e.source) {
            let level = level_of(value, p.last_value, self.engaged, self.disengaged);
            p.last_value = value;
            if value.is_some() {
                p.last_face_ns = now;
            }
            out.push(HriOutput::Engagement {
                person: p.id.clone(),
                level: EngagementLevel {
                    header: Header::at(e.window_end.clone()),
                    level,
                },
            });
        }

        let ids = self.ids();
        let due = match &self.listed {
            None => true,
            Some((before, at)) => *before != ids || now - at >= LIST_REFRESH_NS,
        };
        if due {
            out.extend(lists(&ids, e.window_end.clone()));
            self.listed = Some((ids, now));
        }
        out.extend(
            gone.into_iter()
                .map(|person| HriOutput::PersonGone { person }),
        );
        out
    }

    /// The node is stopping: the lists emptied (so libhri drops the persons at once, as
    /// ROS4HRI's face detector empties its list when it stops) and every person's topics
    /// ended. Nothing when nothing was ever listed.
    pub fn close(&mut self, now: Time) -> Vec<HriOutput> {
        let gone: Vec<String> = std::mem::take(&mut self.persons)
            .into_values()
            .map(|p| p.id)
            .collect();
        let mut out = Vec::new();
        if self.listed.as_ref().is_some_and(|(ids, _)| !ids.is_empty()) {
            out.extend(lists(&[], now));
            self.listed = Some((Vec::new(), 0));
        }
        out.extend(
            gone.into_iter()
                .map(|person| HriOutput::PersonGone { person }),
        );
        out
    }

    /// The ids of the persons reported now, sorted.
    fn ids(&self) -> Vec<String> {
        let mut ids: Vec<String> = self.persons.values().map(|p| p.id.clone()).collect();
        ids.sort();
        ids
    }

    /// A new person's id from its source and first second; never one in use.
    fn new_id(&self, source: &str, first_ns: i64) -> String {
        let mut salt = 0u32;
        loop {
            let mut h = Fnv1a::default();
            h.write(source.as_bytes());
            h.write(&[0]);
            h.write(&first_ns.to_le_bytes());
            h.write(&salt.to_le_bytes());
            let id = format!("{ANONYMOUS_PREFIX}{:08x}", h.finish_u32());
            if !self.persons.values().any(|p| p.id == id) {
                return id;
            }
            salt += 1;
        }
    }
}

fn lists(ids: &[String], stamp: Time) -> [HriOutput; 2] {
    let list = IdsList {
        header: Header::at(stamp),
        ids: ids.to_vec(),
    };
    [HriOutput::Tracked(list.clone()), HriOutput::Known(list)]
}

fn level_of(value: Option<f32>, before: Option<f32>, engaged: f64, disengaged: f64) -> u8 {
    match value {
        None => EngagementLevel::UNKNOWN,
        Some(v) if f64::from(v) >= engaged => EngagementLevel::ENGAGED,
        Some(v) if f64::from(v) <= disengaged => EngagementLevel::DISENGAGED,
        Some(v) => match before {
            Some(b) if v < b => EngagementLevel::DISENGAGING,
            Some(_) => EngagementLevel::ENGAGING,
            None if v >= 0.0 => EngagementLevel::ENGAGING,
            None => EngagementLevel::DISENGAGING,
        },
    }
}

/// FNV-1a, 64 bits: a short id that stays the same across builds and Rust versions (std's
/// hasher promises neither). Not a secret: what it hashes (a camera and a time) is none.
#[derive(Debug)]
struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a {
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    fn finish_u32(&self) -> u32 {
        (self.0 ^ (self.0 >> 32)) as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: i64 = 1_000_000_000;

    fn second(at_s: i64, source: &str, smoothed: Option<f32>) -> ExpectedEngagement {
        ExpectedEngagement {
            source: source.into(),
            window_start: Time::from_nanos((at_s - 1) * S),
            window_end: Time::from_nanos(at_s * S),
            has_faces: smoothed.is_some(),
            smoothed: smoothed.unwrap_or(0.0),
            ..Default::default()
        }
    }

    fn params(timeout_s: f64) -> EngagementClassifierParams {
        EngagementClassifierParams {
            ros4hri_tracked_timeout_s: timeout_s,
            ..Default::default()
        }
    }

    fn levels(out: &[HriOutput]) -> Vec<(String, u8)> {
        out.iter()
            .filter_map(|o| match o {
                HriOutput::Engagement { person, level } => Some((person.clone(), level.level)),
                _ => None,
            })
            .collect()
    }

    fn new_persons(out: &[HriOutput]) -> Vec<String> {
        out.iter()
            .filter_map(|o| match o {
                HriOutput::NewPerson { person, anonymous } => {
                    assert!(anonymous.data, "every person is anonymous");
                    Some(person.clone())
                }
                _ => None,
            })
            .collect()
    }

    fn gone(out: &[HriOutput]) -> Vec<String> {
        out.iter()
            .filter_map(|o| match o {
                HriOutput::PersonGone { person } => Some(person.clone()),
                _ => None,
            })
            .collect()
    }

    /// The tracked and known lists of `out` (they always go out together, equal).
    fn listed(out: &[HriOutput]) -> Option<Vec<String>> {
        let tracked = out.iter().find_map(|o| match o {
            HriOutput::Tracked(l) => Some(l.clone()),
            _ => None,
        });
        let known = out.iter().find_map(|o| match o {
            HriOutput::Known(l) => Some(l.clone()),
            _ => None,
        });
        assert_eq!(tracked, known, "tracked and known differ in {out:?}");
        tracked.map(|l| l.ids)
    }

    fn session(phase: u8, session_id: &str) -> GameState {
        GameState {
            phase,
            session_id: session_id.into(),
            user_id: "1CZ1CL1P".into(),
            ..Default::default()
        }
    }

    #[test]
    fn seconds_become_rep155_levels_of_an_anonymous_person() {
        let mut p = PersonEngagement::new(&params(5.0));
        let mut got = Vec::new();
        let mut people = Vec::new();
        for (t, v) in [
            (1, Some(0.1)),  // between, first: rising from nothing positive
            (2, Some(0.3)),  // rose
            (3, Some(0.7)),  // above 0.5
            (4, Some(0.2)),  // fell
            (5, Some(-0.6)), // below -0.5
            (6, None),       // no face
            (7, Some(-0.2)), // between, after an unknown second
        ] {
            let out = p.on_second(&second(t, "cam/0", v));
            people.extend(new_persons(&out));
            got.extend(levels(&out));
        }
        assert_eq!(people.len(), 1, "one person throughout: {people:?}");
        let person = people[0].clone();
        assert!(person.starts_with(ANONYMOUS_PREFIX), "{person}");
        assert_eq!(person.len(), ANONYMOUS_PREFIX.len() + 8);
        use EngagementLevel as L;
        let want: Vec<(String, u8)> = [
            L::ENGAGING,
            L::ENGAGING,
            L::ENGAGED,
            L::DISENGAGING,
            L::DISENGAGED,
            L::UNKNOWN,
            L::DISENGAGING,
        ]
        .iter()
        .map(|l| (person.clone(), *l))
        .collect();
        assert_eq!(got, want);
    }

    #[test]
    fn new_thresholds_apply_from_the_next_second() {
        let mut p = PersonEngagement::new(&params(5.0));
        let out = p.on_second(&second(1, "cam/0", Some(0.6)));
        let person = new_persons(&out)[0].clone();
        assert_eq!(levels(&out), [(person.clone(), EngagementLevel::ENGAGED)]);
        let mut changed = params(5.0);
        changed.ros4hri_engaged_threshold = 0.8;
        changed.ros4hri_disengaged_threshold = 0.0;
        p.set_thresholds(&changed);
        // 0.5 is below the new 0.8 (ENGAGED before) and fell: DISENGAGING; -0.1 is below 0.
        let out = p.on_second(&second(2, "cam/0", Some(0.5)));
        assert_eq!(
            levels(&out),
            [(person.clone(), EngagementLevel::DISENGAGING)]
        );
        let out = p.on_second(&second(3, "cam/0", Some(-0.1)));
        assert_eq!(levels(&out), [(person, EngagementLevel::DISENGAGED)]);
    }

    /// A new person: `anonymous` first, then its level, then the lists naming it; a person
    /// leaving: the lists without it, then its topics end.
    #[test]
    fn anonymous_comes_before_the_lists_and_topics_end_after_them() {
        let mut p = PersonEngagement::new(&params(2.0));
        // Nobody seen yet: no person, only the (empty) lists.
        let out = p.on_second(&second(1, "cam/0", None));
        assert_eq!(out.len(), 2);
        assert_eq!(listed(&out), Some(vec![]));
        let out = p.on_second(&second(2, "cam/0", Some(0.9)));
        let id = new_persons(&out)[0].clone();
        let kinds: Vec<&str> = out
            .iter()
            .map(|o| match o {
                HriOutput::NewPerson { .. } => "new",
                HriOutput::Engagement { .. } => "level",
                HriOutput::Tracked(_) => "tracked",
                HriOutput::Known(_) => "known",
                HriOutput::PersonGone { .. } => "gone",
            })
            .collect();
        assert_eq!(kinds, ["new", "level", "tracked", "known"]);
        assert_eq!(listed(&out), Some(vec![id.clone()]));

        // No face at 3 and 4 s: still the person (UNKNOWN); at 5 s its face is 3 s old.
        for t in [3, 4] {
            let out = p.on_second(&second(t, "cam/0", None));
            assert_eq!(levels(&out), [(id.clone(), EngagementLevel::UNKNOWN)]);
            assert!(gone(&out).is_empty());
        }
        let out = p.on_second(&second(5, "cam/0", None));
        assert!(levels(&out).is_empty(), "{out:?}");
        assert_eq!(listed(&out), Some(vec![]));
        assert_eq!(gone(&out), std::slice::from_ref(&id));
        assert!(matches!(out.last(), Some(HriOutput::PersonGone { .. })));

        // The face again: a new person, never the old id.
        let out = p.on_second(&second(6, "cam/0", Some(0.9)));
        let again = new_persons(&out);
        assert_eq!(again.len(), 1);
        assert_ne!(again[0], id);
    }

    #[test]
    fn a_session_starting_or_ending_ends_the_person_and_no_id_names_the_user() {
        let mut p = PersonEngagement::new(&params(5.0));
        let before = new_persons(&p.on_second(&second(1, "cam/0", Some(0.9))))[0].clone();
        // A session starts: the person ends and a new one begins.
        p.on_game_state(&session(GameState::SAYING_SEQUENCE, "s1"));
        let out = p.on_second(&second(2, "cam/0", Some(0.9)));
        assert_eq!(gone(&out), std::slice::from_ref(&before));
        let during = new_persons(&out)[0].clone();
        assert_ne!(during, before);
        assert_eq!(listed(&out), Some(vec![during.clone()]));
        // The game's states during the session change nothing; its end does.
        p.on_game_state(&session(GameState::WAITING_FOR_ANSWER, "s1"));
        p.on_game_state(&session(GameState::PAUSED, "s1"));
        let out = p.on_second(&second(3, "cam/0", Some(0.9)));
        assert!(new_persons(&out).is_empty() && gone(&out).is_empty());
        p.on_game_state(&session(GameState::FINISHED, "s1"));
        let out = p.on_second(&second(4, "cam/0", Some(0.9)));
        assert_eq!(gone(&out), std::slice::from_ref(&during));
        let after = new_persons(&out)[0].clone();
        for id in [&before, &during, &after] {
            assert!(!id.to_lowercase().contains("1cz1cl1p"), "{id}");
            assert!(
                id.chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'),
                "{id} is a ROS name token"
            );
        }
        // The same session again is no change.
        p.on_game_state(&session(GameState::FINISHED, "s1"));
        let out = p.on_second(&second(5, "cam/0", Some(0.9)));
        assert!(gone(&out).is_empty());
    }

    #[test]
    fn the_lists_go_out_on_change_and_every_second() {
        let mut p = PersonEngagement::new(&params(5.0));
        // Two cameras: each second, two seconds of input; the lists at most once a second
        // when nothing changes.
        let a = new_persons(&p.on_second(&second(1, "cam/0", Some(0.9))))[0].clone();
        let out = p.on_second(&second(1, "cam/1", Some(0.9)));
        let b = new_persons(&out)[0].clone();
        let mut both = vec![a.clone(), b.clone()];
        both.sort();
        assert_eq!(listed(&out), Some(both.clone()));
        let mut lists = 0;
        for t in 2..=6 {
            for cam in ["cam/0", "cam/1"] {
                let out = p.on_second(&second(t, cam, Some(0.9)));
                if let Some(ids) = listed(&out) {
                    assert_eq!(ids, both);
                    lists += 1;
                }
            }
        }
        assert_eq!(lists, 5, "once a second");
    }

    #[test]
    fn closing_empties_the_lists_and_ends_every_person() {
        let mut p = PersonEngagement::new(&params(5.0));
        assert!(
            p.close(Time::from_nanos(S)).is_empty(),
            "nothing listed yet"
        );
        let id = new_persons(&p.on_second(&second(1, "cam/0", Some(0.9))))[0].clone();
        let out = p.close(Time::from_nanos(2 * S));
        assert_eq!(listed(&out), Some(vec![]));
        assert_eq!(gone(&out), [id]);
        assert!(p.close(Time::from_nanos(3 * S)).is_empty());
    }

    #[test]
    fn ids_are_stable_and_distinct_per_source_and_first_second() {
        let p = PersonEngagement::new(&params(5.0));
        let a = p.new_id("cam/0", S);
        assert_eq!(a, p.new_id("cam/0", S));
        assert_ne!(a, p.new_id("cam/1", S));
        assert_ne!(a, p.new_id("cam/0", 2 * S));
        // The FNV-1a reference value of the empty input, so the hash is the published one.
        assert_eq!(Fnv1a::default().0, 0xcbf2_9ce4_8422_2325);
        let mut h = Fnv1a::default();
        h.write(b"a");
        assert_eq!(h.0, 0xaf63_dc4c_8601_ec8c);
    }
}
