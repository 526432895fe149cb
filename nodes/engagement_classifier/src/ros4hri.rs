//! Engagement the ROS4HRI way (REP-155): each second's expected engagement becomes an
//! `hri_msgs/EngagementLevel` of a person, and the persons seen lately an `hri_msgs/IdsList`.
//! The person is the session's user (`user_<id>`, from the game state) while a session runs,
//! else the camera's face (`face_<camera>_<face>`). Levels, with thresholds from parameters:
//! no face in the second, UNKNOWN; smoothed engagement at or above the engaged threshold,
//! ENGAGED; at or below the disengaged one, DISENGAGED; between them, ENGAGING when it rose
//! since the person's last second and DISENGAGING when it fell (REP-155: starting to look
//! towards, or away from, the robot). Sans-IO: messages in, messages out.

use crate::params::EngagementClassifierParams;
use qt_therapy_msgs::hri_msgs::{EngagementLevel, IdsList};
use qt_therapy_msgs::std_msgs::Header;
use qt_therapy_msgs::topics::person_id;
use qt_therapy_msgs::{ExpectedEngagement, GameState};
use std::collections::BTreeMap;

/// What to publish.
#[derive(Debug, Clone, PartialEq)]
pub enum HriOutput {
    /// A person's level, for `/humans/persons/<person>/engagement_status`.
    Engagement {
        person: String,
        level: EngagementLevel,
    },
    /// The persons tracked changed.
    Tracked(IdsList),
}

/// The mapping from seconds to ROS4HRI levels.
#[derive(Debug, Clone)]
pub struct PersonEngagement {
    engaged: f64,
    disengaged: f64,
    timeout_ns: i64,
    /// The session's person while one runs.
    user: Option<String>,
    /// Per person: the last smoothed engagement seen (None: no face) and when (ns).
    last: BTreeMap<String, (Option<f32>, i64)>,
    tracked: Vec<String>,
}

impl PersonEngagement {
    pub fn new(params: &EngagementClassifierParams) -> Self {
        PersonEngagement {
            engaged: params.ros4hri_engaged_threshold,
            disengaged: params.ros4hri_disengaged_threshold,
            timeout_ns: (params.ros4hri_tracked_timeout_s * 1e9) as i64,
            user: None,
            last: BTreeMap::new(),
            tracked: Vec::new(),
        }
    }

    /// The game's state: a running session's user is the person from now on.
    pub fn on_game_state(&mut self, g: &GameState) {
        let in_session = !g.user_id.is_empty()
            && !g.session_id.is_empty()
            && g.phase != GameState::IDLE
            && !GameState::is_ended(g.phase);
        self.user = in_session.then(|| person_id("user", &g.user_id));
    }

    /// One closed second of one source.
    pub fn on_second(&mut self, e: &ExpectedEngagement) -> Vec<HriOutput> {
        let now = e.window_end.to_nanos();
        let person = self
            .user
            .clone()
            .unwrap_or_else(|| person_id("face", &e.source));
        let value = e.has_faces.then_some(e.smoothed);
        let before = self.last.get(&person).and_then(|(v, _)| *v);
        let level = match value {
            None => EngagementLevel::UNKNOWN,
            Some(v) if f64::from(v) >= self.engaged => EngagementLevel::ENGAGED,
            Some(v) if f64::from(v) <= self.disengaged => EngagementLevel::DISENGAGED,
            Some(v) => match before {
                Some(b) if v < b => EngagementLevel::DISENGAGING,
                Some(_) => EngagementLevel::ENGAGING,
                None if v >= 0.0 => EngagementLevel::ENGAGING,
                None => EngagementLevel::DISENGAGING,
            },
        };
        self.last.insert(person.clone(), (value, now));
        let mut out = vec![HriOutput::Engagement {
            person,
            level: EngagementLevel {
                header: Header::at(e.window_end.clone()),
                level,
            },
        }];
        let timeout = self.timeout_ns;
        self.last.retain(|_, (_, at)| now - *at <= timeout);
        let tracked: Vec<String> = self.last.keys().cloned().collect();
        if tracked != self.tracked {
            self.tracked = tracked.clone();
            out.push(HriOutput::Tracked(IdsList {
                header: Header::at(e.window_end.clone()),
                ids: tracked,
            }));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qt_therapy_msgs::builtin_interfaces::Time;

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

    fn levels(out: &[HriOutput]) -> Vec<(String, u8)> {
        out.iter()
            .filter_map(|o| match o {
                HriOutput::Engagement { person, level } => Some((person.clone(), level.level)),
                HriOutput::Tracked(_) => None,
            })
            .collect()
    }

    #[test]
    fn seconds_become_rep155_levels_of_the_session_user_or_the_face() {
        let mut p = PersonEngagement::new(&EngagementClassifierParams::default());
        let face = "face_cam_0";
        let mut got = Vec::new();
        for (t, v) in [
            (1, Some(0.1)),  // between, first: rising from nothing positive
            (2, Some(0.3)),  // rose
            (3, Some(0.7)),  // above 0.5
            (4, Some(0.2)),  // fell
            (5, Some(-0.6)), // below -0.5
            (6, None),       // no face
            (7, Some(-0.2)), // between, after an unknown second
        ] {
            got.extend(levels(&p.on_second(&second(t, "cam/0", v))));
        }
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
        .map(|l| (face.to_string(), *l))
        .collect();
        assert_eq!(got, want);

        // A session starts: its user is the person; it ends: the face again.
        p.on_game_state(&GameState {
            phase: GameState::SAYING_SEQUENCE,
            session_id: "s1".into(),
            user_id: "1CZ1CL1P".into(),
            ..Default::default()
        });
        let out = p.on_second(&second(8, "cam/0", Some(0.9)));
        assert_eq!(levels(&out), [("user_1CZ1CL1P".to_string(), L::ENGAGED)]);
        assert!(out.contains(&HriOutput::Tracked(IdsList {
            header: Header::at(Time::from_nanos(8 * S)),
            ids: vec![face.into(), "user_1CZ1CL1P".into()],
        })));
        p.on_game_state(&GameState {
            phase: GameState::FINISHED,
            session_id: "s1".into(),
            user_id: "1CZ1CL1P".into(),
            ..Default::default()
        });
        assert_eq!(
            levels(&p.on_second(&second(9, "cam/0", Some(0.9))))[0].0,
            face
        );
        // The user's last second is more than 5 s old at 14 s: no longer tracked.
        let out = p.on_second(&second(14, "cam/0", Some(0.9)));
        assert!(out.contains(&HriOutput::Tracked(IdsList {
            header: Header::at(Time::from_nanos(14 * S)),
            ids: vec![face.into()],
        })));
    }
}
