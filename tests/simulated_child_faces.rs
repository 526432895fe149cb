//! The simulated child's face, classified by the real engagement model, shows the engagement
//! its user model predicts: the two nodes agree on what a SYNTHETIC face means.

use engagement_classifier::EngagementModel;
use qt_therapy_msgs::GameState;
use sequence_game::{Outcome, Prediction, UserModelTable};
use simulated_child::{ChildOutput, ChildParams, SimulatedChild};

fn table(p: f64, e_success: f64, e_failure: f64) -> UserModelTable {
    UserModelTable::tabulate(
        0,
        |_| Prediction { mean: p, std: 0.0 },
        |_, o| Prediction {
            mean: if o == Outcome::Success {
                e_success
            } else {
                e_failure
            },
            std: 0.0,
        },
    )
}

fn state(phase: u8, index: u8, level: u8) -> GameState {
    GameState {
        phase,
        session_id: "s".into(),
        sequence_index: index,
        level,
        feedback: 0,
        last_score: 1,
        ..Default::default()
    }
}

#[test]
fn classified_face_follows_the_predicted_engagement() {
    let model_path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../nodes/engagement_classifier/models/synthetic_engagement.json"
    );
    let model =
        EngagementModel::load(std::path::Path::new(model_path)).expect("shipped synthetic model");
    assert_eq!(
        engagement_classifier::OPENFACE_FEATURES,
        qt_therapy_msgs::OPENFACE_FEATURES
    );
    for target in [0.6, -0.4] {
        let mut child =
            SimulatedChild::new(ChildParams::default(), table(0.5, target, target)).expect("child");
        child.on_game_state(&state(GameState::SAYING_SEQUENCE, 1, 2));
        assert_eq!(child.target_engagement(), target);
        let (mut plus, mut minus) = (0u32, 0u32);
        let mut t = 0;
        // Two minutes of camera frames.
        while t < 120_000_000_000 {
            t += 100_000_000;
            for out in child.poll(t) {
                if let ChildOutput::Frame(f) = out
                    && f.success
                {
                    let features: [f32; 32] =
                        f.features.as_slice().try_into().expect("32 features");
                    if model.predict_f32(&features).probability >= 0.5 {
                        plus += 1
                    } else {
                        minus += 1
                    }
                }
            }
        }
        let measured = (f64::from(plus) - f64::from(minus)) / f64::from(plus + minus);
        assert!(
            (measured - target).abs() < 0.2,
            "target {target}, classified {measured}"
        );
    }
}
