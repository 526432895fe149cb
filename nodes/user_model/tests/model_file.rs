//! The model file: a fitted set saves and loads back to identical predictions, the committed
//! synthetic model is what the synthetic study fits to, tables hold every prediction, and new
//! users are assigned to the nearest cluster.

use sequence_game::{ModelInput, Outcome};
use std::path::Path;
use user_model::simulate::{StudySpec, simulate_study};
use user_model::{FitOptions, Kernel, UserModelSet, fit};

#[test]
fn save_then_load_predicts_identically_for_every_kernel() {
    let records = simulate_study(&StudySpec::default());
    let dir = tempfile::tempdir().expect("temp dir");
    for kernel in [
        Kernel::AUTHORS,
        Kernel::Rbf { length_scale: 1.0 },
        Kernel::Matern {
            length_scale: 1.0,
            nu: 2.5,
        },
    ] {
        let set = fit(
            &records,
            &FitOptions {
                kernel,
                ..Default::default()
            },
        )
        .expect("fits");
        let path = dir.path().join(format!("{}.json", kernel.name()));
        set.save(&path).expect("saves");
        let back = UserModelSet::load(&path).expect("loads");
        assert_eq!(back.file(), set.file());
        assert_eq!(back.tables(), set.tables(), "{kernel:?}");
    }
}

#[test]
fn tables_hold_clamped_predictions_with_uncertainty() {
    let set = fit(
        &simulate_study(&StudySpec::default()),
        &FitOptions::default(),
    )
    .expect("fits");
    let tables = set.tables();
    assert_eq!(tables.len(), 2);
    for t in &tables {
        t.validate().expect("valid table");
        // Unobserved inputs are uncertain, observed ones less so.
        let observed: Vec<f64> = set.file().clusters[t.cluster]
            .success
            .inputs
            .iter()
            .filter_map(|x| {
                ModelInput::all()
                    .find(|i| &user_model::model::encode(*i, None) == x)
                    .map(|i| t.success(i).std)
            })
            .collect();
        let max_std = t.success.iter().map(|p| p.std).fold(0.0, f64::max);
        assert!(observed.iter().all(|s| *s < 1e-3), "{observed:?}");
        assert!(max_std > 0.01, "{max_std}");
        for i in ModelInput::all() {
            for o in Outcome::ALL {
                assert_eq!(t.engagement(i, o), t.engagement[i.engagement_index(o)]);
            }
        }
    }
}

#[test]
fn committed_synthetic_model_is_what_the_synthetic_study_fits_to() {
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/synthetic_study_c2.json");
    let model = UserModelSet::load(&committed).expect("loads");
    let set = fit(
        &simulate_study(&StudySpec::default()),
        &FitOptions::default(),
    )
    .expect("fits");
    let mut fresh = set.file().clone();
    fresh.provenance = model.file().provenance.clone();
    assert_eq!(&fresh, model.file());
    assert_eq!(set.tables(), model.tables());
}

#[test]
fn new_users_go_to_the_nearest_cluster() {
    let set = fit(
        &simulate_study(&StudySpec::default()),
        &FitOptions::default(),
    )
    .expect("fits");
    let engaged = set
        .assign_cluster(&[0.95, 0.5, 0.9, 0.6, 0.5, 0.55])
        .expect("assigns");
    let disengaged = set
        .assign_cluster(&[0.95, -0.6, 0.9, -0.5, 0.5, -0.7])
        .expect("assigns");
    assert_ne!(engaged, disengaged);
    assert!(set.file().clusters[engaged].levels[0].engagement_mean > 0.0);
    assert!(set.file().clusters[disengaged].levels[0].engagement_mean < 0.0);
    let e = set
        .assign_cluster(&[1.2, 0.0, 0.5, 0.0, 0.5, 0.0])
        .expect_err("P > 1");
    assert!(e.to_string().contains("value 0 = 1.2"), "{e}");
    assert!(
        set.assign_cluster(&[0.5, f64::NAN, 0.5, 0.0, 0.5, 0.0])
            .is_err()
    );
}
