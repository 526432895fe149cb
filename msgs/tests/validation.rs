//! Out-of-range fields and unknown enum values are refused with a reason naming the field.

use qt_therapy_msgs::*;

fn reason<M: Validate>(m: &M) -> String {
    m.validate().expect_err("must be refused").to_string()
}

#[test]
fn features_must_be_32_finite_values() {
    let mut f = OpenFaceFeatures {
        success: true,
        confidence: 0.9,
        features: vec![0.0; 32],
        ..Default::default()
    };
    assert!(f.validate().is_ok());
    f.features.pop();
    assert!(reason(&f).contains("has 31 features, expected 32"));
    f.features = vec![0.0; 32];
    f.features[5] = f32::NAN;
    assert!(reason(&f).contains("pose_Rz"));
    // A lost face may carry NaN: it is reported as missing, not refused.
    f.success = false;
    assert!(f.validate().is_ok());
}

#[test]
fn levels_commands_and_states_are_range_checked() {
    let s = GameState {
        level: 4,
        ..Default::default()
    };
    assert!(reason(&s).contains("level = 4"));
    let c = TherapistCommand {
        command: 9,
        session_id: "s".into(),
        ..Default::default()
    };
    assert!(reason(&c).contains("command = 9"));
    let c = TherapistCommand {
        command: TherapistCommand::OVERRIDE_LEVEL,
        session_id: "s".into(),
        level: 0,
        ..Default::default()
    };
    assert!(reason(&c).contains("level = 0"));
    let c = TherapistCommand {
        command: TherapistCommand::START,
        session_id: "s".into(),
        ..Default::default()
    };
    assert!(reason(&c).contains("user_id is empty"));
    let r = DecideActionRequest {
        session_id: "s".into(),
        state: BehaviourState {
            level: 0,
            feedback: 0,
            previous_score: 0,
        },
        step: 2,
        ..Default::default()
    };
    assert!(reason(&r).contains("only step 1 starts"));
    let r = PredictUserRequest {
        cluster: 0,
        level: 1,
        feedback: 3,
        previous_score: 0,
        outcome: 1,
    };
    assert!(reason(&r).contains("feedback = 3"));
    let a = TabletAnswer {
        session_id: "s".into(),
        answer: vec!["HAPPY".into()],
        ..Default::default()
    };
    assert!(reason(&a).contains("answer[0]"));
    let a = TabletAnswer {
        session_id: "s\u{7}".into(),
        ..Default::default()
    };
    assert!(reason(&a).contains("control characters"));
    let v = AssignClusterRequest {
        user_vector: vec![0.5; 5],
    };
    assert!(reason(&v).contains("6"));
}

#[test]
fn a_result_knows_its_session_length_and_engagement_period() {
    use qt_therapy_msgs::builtin_interfaces::Time;
    let good = SequenceResult {
        session_id: "s".into(),
        sequence_index: 5,
        sequences_planned: 5,
        level: 1,
        sequence: vec!["happy".into(); 3],
        outcome: 1,
        engagement_period_start: Time::from_nanos(1_000),
        engagement_period_end: Time::from_nanos(2_000),
        ..Default::default()
    };
    assert_eq!(good.validate(), Ok(()));
    let past_the_end = SequenceResult {
        sequence_index: 6,
        ..good.clone()
    };
    assert!(reason(&past_the_end).contains("past the session's 5 sequences"));
    let unknown_length = SequenceResult {
        sequences_planned: 0,
        ..good.clone()
    };
    assert!(reason(&unknown_length).contains("sequences_planned = 0"));
    let backwards = SequenceResult {
        engagement_period_start: Time::from_nanos(3_000),
        ..good.clone()
    };
    assert!(reason(&backwards).contains("engagement_period_start is after"));
    let refused = GameState {
        command_outcome: 4,
        ..Default::default()
    };
    assert!(reason(&refused).contains("command_outcome"));
}

#[test]
fn proposals_are_range_checked() {
    let mut p = ActionProposal {
        session_id: "s".into(),
        step: 2,
        state: BehaviourState {
            level: 1,
            feedback: 0,
            previous_score: 1,
        },
        action: 1,
        level: 2,
        temperature: 250.0,
        success_std: -1.0,
        countdown: 5.0,
        ..Default::default()
    };
    assert!(p.validate().is_ok(), "{:?}", p.validate());
    p.step = 0;
    assert!(reason(&p).contains("step = 0"));
    p.step = 2;
    p.success_std = -0.5;
    assert!(reason(&p).contains("success_std -0.5"));
    p.success_std = 0.2;
    // Settled: what plays must be an action too.
    p.status = ActionProposal::ACCEPTED;
    assert!(reason(&p).contains("played_level = 0"));
    p.played_action = 1;
    p.played_level = 2;
    assert!(p.validate().is_ok());
    p.status = 5;
    assert!(reason(&p).contains("status = 5"));
}
