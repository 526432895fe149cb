//! The real MigrAVE study (beside the repository in ../shared): read directly, it fits into the
//! paper's two clusters of 11 and 9 users with the authors' per-cluster numbers, and the
//! committed model file is what `user_model fit` makes of it. Skips where ../shared is absent.
//! Also the recorded sample sessions in bags/ (skipped where there are none): the bag reader's
//! records carry the per-second engagement the game manager computed live.

use std::path::{Path, PathBuf};
use user_models::{FitOptions, UserModelSet, fit};

fn study() -> Option<PathBuf> {
    let shared = std::env::var_os("QT_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
    let dir = shared.join("data/migrave-study");
    if dir.join("sequences.csv").exists() {
        Some(dir)
    } else {
        eprintln!("skipping: ../shared not found");
        None
    }
}

#[test]
fn reads_the_study_with_previous_scores() {
    let Some(dir) = study() else { return };
    let records = user_models::data::read_study(&dir).expect("reads the study");
    assert_eq!(records.len(), 200);
    let users: std::collections::BTreeSet<&str> =
        records.iter().map(|r| r.user_id.as_str()).collect();
    assert_eq!(users.len(), 20);
    for pair in records.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        if a.user_id == b.user_id {
            assert_eq!(b.previous_score, a.score, "{} at {}", b.user_id, b.time);
            assert!(b.time > a.time);
        } else {
            assert_eq!(b.previous_score, 0);
        }
    }
    assert!(records.iter().all(|r| !r.engagement_per_second.is_empty()));
}

/// The authors' per-cluster (P(success|L), E|L) for L = 1, 2, 3 (REFERENCE.md).
const PAPER: [[(f64, f64); 3]; 2] = [
    [(0.943, 0.508), (0.854, 0.641), (0.529, 0.569)],
    [(0.970, -0.610), (0.935, -0.512), (0.462, -0.708)],
];

#[test]
fn real_study_gives_the_papers_clusters_and_numbers() {
    let Some(dir) = study() else { return };
    let records = user_models::data::read_study(&dir).expect("reads the study");
    let set = fit(&records, &FitOptions::default()).expect("fits");
    let clusters = &set.file().clusters;
    assert_eq!(clusters.len(), 2);
    // Match our clusters to the paper's by the sign of the engagement.
    for c in clusters {
        let paper = if c.levels[0].engagement_mean > 0.0 {
            &PAPER[0]
        } else {
            &PAPER[1]
        };
        let size = if std::ptr::eq(paper, &PAPER[0]) {
            11
        } else {
            9
        };
        assert_eq!(c.users.len(), size, "cluster {}", c.cluster);
        for (l, (p, e)) in c.levels.iter().zip(paper) {
            assert!(
                (l.success_mean - p).abs() < 5e-4 && (l.engagement_mean - e).abs() < 5e-4,
                "cluster {} level {}: ({}, {}) vs the paper's ({p}, {e})",
                c.cluster,
                l.level,
                l.success_mean,
                l.engagement_mean
            );
        }
    }
    // Every user's own vector is assigned to the cluster the fit gave them.
    for u in &set.file().users {
        let v: [f64; 6] = u.vector.as_slice().try_into().expect("6 values");
        assert_eq!(
            set.assign_cluster(&v).expect("assigns"),
            u.cluster,
            "{}",
            u.user
        );
    }
}

#[test]
fn committed_model_is_what_fit_makes_of_the_study() {
    let Some(dir) = study() else { return };
    let committed = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../nodes/user_model/models/migrave_study_c2.json");
    let model = UserModelSet::load(&committed).expect("committed model loads");
    let records = user_models::data::read_study(&dir).expect("reads the study");
    let set = fit(&records, &FitOptions::default()).expect("fits");
    let mut fresh = set.file().clone();
    fresh.provenance = model.file().provenance.clone();
    assert_eq!(&fresh, model.file());
    assert_eq!(set.tables(), model.tables());
}

#[test]
fn sigma_of_the_papers_fit_means_never_seen_and_with_a_fitted_noise_how_much_was_seen() {
    use sequence_game::ModelInput;
    use user_models::NoiseModel;
    use user_models::model::encode;
    let Some(dir) = study() else { return };
    let records = user_models::data::read_study(&dir).expect("reads the study");
    let paper = fit(&records, &FitOptions::default()).expect("fits");
    let fitted = fit(
        &records,
        &FitOptions {
            noise_model: NoiseModel::FittedPerSequence,
            ..Default::default()
        },
    )
    .expect("fits");
    // The clustering does not depend on the GPs' noise.
    assert_eq!(paper.file().users, fitted.file().users);
    for (k, c) in fitted.file().clusters.iter().enumerate() {
        let sizes = c.success.group_sizes.as_ref().expect("group sizes kept");
        // A Bernoulli's variance is at most 0.25; the study's success rates are about 0.8.
        assert!(
            (0.02..0.25).contains(&c.success.noise),
            "{}",
            c.success.noise
        );
        let (mut once, mut often) = (Vec::new(), Vec::new());
        for input in ModelInput::all() {
            let seen = c
                .success
                .inputs
                .iter()
                .position(|x| *x == encode(input, None))
                .map_or(0, |i| sizes[i]);
            let p = paper.tables()[k].success(input).std;
            let f = fitted.tables()[k].success(input).std;
            // The paper's σ: about 0 wherever the study has a group, one sequence or thirty.
            if seen > 0 {
                assert!(
                    p < 1e-3,
                    "cluster {k} {input:?}: σ {p} with {seen} sequence(s)"
                );
            } else {
                assert!(p > 0.2, "cluster {k} {input:?}: σ {p}, never seen");
            }
            // The fitted noise's σ: never 0, never the prior's 1.
            assert!((0.03..0.3).contains(&f), "cluster {k} {input:?}: σ {f}");
            match seen {
                1 => once.push(f),
                n if n >= 5 => often.push(f),
                _ => {}
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        assert!(!once.is_empty() && !often.is_empty());
        assert!(
            mean(&once) > mean(&often) + 0.02,
            "cluster {k}: σ {} where one sequence was seen, {} where five or more",
            mean(&once),
            mean(&often)
        );
    }
}

#[test]
fn recorded_session_bags_give_the_game_managers_engagement() {
    use qt_therapy_msgs::SequenceResult;
    use qt_therapy_msgs::topics::SEQUENCE_RESULT;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bags");
    let bags = if dir.is_dir() {
        user_models::data::bag::bags_in(&dir).expect("lists bags/")
    } else {
        vec![]
    };
    if bags.is_empty() {
        eprintln!("skipping: no recorded session bag in bags/");
        return;
    }
    for path in &bags {
        let read = user_models::data::bag::read_bag(path).expect("reads the bag");
        assert!(read.warnings.is_empty(), "{:?}", read.warnings);
        let results = bag_file::BagReader::open(path)
            .expect("opens")
            .messages::<SequenceResult>(SEQUENCE_RESULT.name)
            .expect("results");
        assert_eq!(read.records.len(), results.len(), "{}", path.display());
        for m in &results {
            let m = &m.message;
            let r = read
                .records
                .iter()
                .filter(|r| r.session_id == m.session_id)
                .nth(usize::from(m.sequence_index) - 1)
                .expect("the sequence's record");
            let game: Vec<f64> = m
                .engagement_per_second
                .iter()
                .map(|v| f64::from(*v))
                .collect();
            assert_eq!(
                (
                    r.engagement_per_second.clone(),
                    r.user_id.as_str(),
                    r.level.get(),
                    u8::from(r.feedback)
                ),
                (game, m.user_id.as_str(), m.level, m.feedback),
                "{} sequence {}",
                path.display(),
                m.sequence_index
            );
            assert_eq!(r.previous_score, m.state.previous_score);
            assert_eq!(r.outcome.sign(), m.outcome);
        }
    }
}
