//! Per-frame -> per-second behaviour of the sans-IO core: windows of message time, sources
//! that interleave, seconds without a face, late frames, bad frames, smoothing.

use engagement_classifier::aggregate::{AggregateError, AggregatorConfig, SecondAggregator};
use engagement_classifier::smoothing::smooth_series;
use engagement_classifier::synthetic::{SyntheticSpec, generate};
use engagement_classifier::{
    EngagementClassifierParams, EngagementEstimator, EngagementSecond, FaceFrame, FrameError,
    FrameOutcome, MissingReason,
};
use std::path::Path;

const S: i64 = 1_000_000_000;

fn config() -> AggregatorConfig {
    EngagementClassifierParams::default().aggregator_config()
}

fn collect(agg: &mut SecondAggregator, frames: &[(u32, i64, Option<i8>)]) -> Vec<EngagementSecond> {
    let mut out = Vec::new();
    for &(source, t, label) in frames {
        agg.add(source, t, label, &mut |s| out.push(*s))
            .expect("frame accepted");
    }
    agg.flush(&mut |s| out.push(*s));
    out
}

#[test]
fn a_second_reports_the_mean_label_and_counts() {
    let mut agg = SecondAggregator::new(AggregatorConfig {
        smoothing_alpha: 1.0,
        ..config()
    });
    // second 10: three engaged, one disengaged, one missing; second 11: one disengaged
    let frames = [
        (0, 10 * S, Some(1)),
        (0, 10 * S + S / 4, Some(1)),
        (0, 10 * S + S / 2, None),
        (0, 10 * S + 3 * S / 4, Some(-1)),
        (0, 11 * S - 1, Some(1)),
        (0, 11 * S, Some(-1)),
    ];
    let out = collect(&mut agg, &frames);
    assert_eq!(out.len(), 2);
    assert_eq!(
        (out[0].window_start_ns, out[0].window_end_ns),
        (10 * S, 11 * S)
    );
    assert_eq!(out[0].engagement, Some(0.5));
    assert_eq!(out[0].smoothed_engagement, Some(0.5));
    assert_eq!((out[0].frame_count(), out[0].missing_frames), (4, 1));
    assert_eq!(out[1].engagement, Some(-1.0));
}

#[test]
fn a_second_without_a_face_is_reported_as_such_not_as_disengaged() {
    let mut agg = SecondAggregator::new(config());
    let frames = [
        (0, 5 * S, Some(1)),
        (0, 6 * S + 10, None),
        (0, 6 * S + 20, None),
        (0, 8 * S, Some(1)),
    ];
    let out = collect(&mut agg, &frames);
    let seconds: Vec<i64> = out.iter().map(|s| s.window_start_ns / S).collect();
    assert_eq!(seconds, vec![5, 6, 7, 8]);
    for empty in &out[1..3] {
        assert_eq!(empty.engagement, None);
        assert_eq!(empty.smoothed_engagement, None);
        assert_eq!(empty.frame_count(), 0);
    }
    assert_eq!(out[1].missing_frames, 2);
    // smoothing skips the empty seconds, as the authors' per-second table has no rows for them
    assert_eq!(out[3].smoothed_engagement, Some(1.0));
}

#[test]
fn interleaved_sources_keep_their_own_seconds() {
    let mut agg = SecondAggregator::new(config());
    let mut frames = Vec::new();
    for k in 0..90i64 {
        let t = 100 * S + k * S / 30; // 3 s at 30 fps
        frames.push((7, t, Some(1)));
        frames.push((3, t + 1000, Some(if k % 3 == 0 { 1 } else { -1 })));
    }
    let out = collect(&mut agg, &frames);
    assert_eq!(out.len(), 6);
    for s in &out {
        assert_eq!(s.frame_count(), 30);
        let want = if s.source == 7 { 1.0 } else { -1.0 / 3.0 };
        assert!((s.engagement.expect("face") - want).abs() < 1e-12, "{s:?}");
    }
    // each second lists the sources in the order they appeared
    assert_eq!((out[0].source, out[1].source), (7, 3));
}

#[test]
fn late_frames_within_the_allowed_lateness_count_older_ones_are_refused() {
    let mut agg = SecondAggregator::new(config()); // max_lateness 0.2 s
    let mut out = Vec::new();
    let mut emit = |s: &EngagementSecond| out.push(*s);
    agg.add(0, 20 * S + S / 2, Some(1), &mut emit).expect("ok");
    agg.add(1, 21 * S + S / 10, Some(1), &mut emit).expect("ok");
    // camera 0's frame from second 20 arrives after camera 1's from 21.1 s: still counts
    agg.add(0, 20 * S + 9 * S / 10, Some(-1), &mut emit)
        .expect("within lateness");
    agg.add(1, 21 * S + S / 2, Some(1), &mut emit).expect("ok");
    let err = agg
        .add(0, 20 * S + 95 * S / 100, Some(1), &mut emit)
        .expect_err("too late");
    assert!(
        matches!(err, AggregateError::LateFrame { source_id: 0, .. }),
        "{err}"
    );
    agg.flush(&mut emit);
    let second_20 = out
        .iter()
        .find(|s| s.source == 0 && s.window_start_ns == 20 * S)
        .expect("20");
    assert_eq!(second_20.engagement, Some(0.0));
    // camera 1 appeared in second 21: it does not report second 20
    assert!(
        !out.iter()
            .any(|s| s.source == 1 && s.window_start_ns == 20 * S)
    );
}

#[test]
fn a_source_that_stops_sending_retires_after_the_timeout() {
    let mut agg = SecondAggregator::new(config()); // timeout 5 s
    let mut frames = vec![(1, 0, Some(1))];
    frames.extend((0..20).map(|k| (2, k * S, Some(-1))));
    let out = collect(&mut agg, &frames);
    let source_1: Vec<_> = out.iter().filter(|s| s.source == 1).collect();
    assert_eq!(source_1.len(), 5, "seconds 0..5, then retired");
    assert!(source_1[1..].iter().all(|s| s.engagement.is_none()));
    assert_eq!(out.iter().filter(|s| s.source == 2).count(), 20);
}

#[test]
fn a_step_of_the_frames_clock_restarts_the_seconds_and_loses_none() {
    for by in [-3600 * S, 7200 * S] {
        let mut agg = SecondAggregator::new(config());
        let mut out = Vec::new();
        let mut emit = |s: &EngagementSecond| out.push(*s);
        // 10 frames a second over seconds 100..103, then the clock steps mid-second 103.
        for k in 0..35 {
            agg.add(0, 100 * S + k * S / 10, Some(1), &mut emit)
                .expect("on time");
        }
        // Without a restart a step back makes every later frame late.
        if by < 0 {
            let err = agg.add(0, 103 * S + S / 2 + by, Some(-1), &mut emit);
            assert!(matches!(err, Err(AggregateError::LateFrame { .. })));
        }
        agg.restart_at(103 * S + S / 2 + by, &mut emit);
        for k in 0..25 {
            agg.add(0, 103 * S + S / 2 + by + k * S / 10, Some(-1), &mut emit)
                .expect("counted after the restart");
        }
        agg.flush(&mut emit);
        // Seconds 100..102 whole and 103 cut at the step, then 103+by (from the half
        // second on), 104+by and 105+by: every frame in one second, once.
        assert_eq!(
            out.iter()
                .map(|s| (s.window_start_ns, s.frame_count()))
                .collect::<Vec<_>>(),
            vec![
                (100 * S, 10),
                (101 * S, 10),
                (102 * S, 10),
                (103 * S, 5),
                (103 * S + by, 5),
                (104 * S + by, 10),
                (105 * S + by, 10),
            ],
            "{by}"
        );
        // No second of the gap a forward step skipped is reported as one without a face.
        assert!(out.iter().all(|s| s.engagement.is_some()), "{by}");
    }
}

#[test]
fn too_many_sources_is_an_error_value() {
    let mut agg = SecondAggregator::new(AggregatorConfig {
        max_sources: 2,
        ..config()
    });
    let mut emit = |_: &EngagementSecond| {};
    agg.add(1, 0, Some(1), &mut emit).expect("ok");
    agg.add(2, 0, Some(1), &mut emit).expect("ok");
    let err = agg.add(3, 0, Some(1), &mut emit).expect_err("full");
    assert!(err.to_string().contains("max_sources = 2"), "{err}");
}

fn estimator() -> EngagementEstimator {
    // The defaults name the shipped synthetic model, relative to the workspace root.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    EngagementEstimator::from_params(&EngagementClassifierParams::default(), &root)
        .expect("shipped synthetic model loads")
}

#[test]
fn setup_errors_name_the_model_file() {
    let params = EngagementClassifierParams {
        model_file: "no/such/model.json".into(),
        ..Default::default()
    };
    let err = EngagementEstimator::from_params(&params, Path::new(".")).expect_err("no file");
    assert!(err.to_string().contains("no/such/model.json"), "{err}");
    let params = EngagementClassifierParams {
        smoothing_alpha: 2.0,
        ..Default::default()
    };
    let err = EngagementEstimator::from_params(&params, Path::new(".")).expect_err("bad alpha");
    assert!(err.to_string().contains("smoothing_alpha"), "{err}");
}

#[test]
fn frames_without_a_usable_face_are_missing_and_bad_frames_are_errors() {
    let mut est = estimator();
    let mut out = Vec::new();
    let mut emit = |s: &EngagementSecond| out.push(*s);
    let features = [0.5f32; 32];
    let frame = |t, success, confidence, features| FaceFrame {
        stamp_ns: t,
        source: 0,
        detection_success: success,
        confidence,
        features,
    };
    let r = est.on_frame(&frame(0, false, 0.99, &features), &mut emit);
    assert_eq!(r, Ok(FrameOutcome::Missing(MissingReason::DetectionFailed)));
    let r = est.on_frame(&frame(1, true, 0.2, &features), &mut emit);
    assert_eq!(r, Ok(FrameOutcome::Missing(MissingReason::LowConfidence)));
    let r = est.on_frame(&frame(2, true, f32::NAN, &features), &mut emit);
    assert_eq!(r, Ok(FrameOutcome::Missing(MissingReason::LowConfidence)));
    let r = est.on_frame(&frame(3, true, 0.9, &features[..31]), &mut emit);
    assert!(
        matches!(r, Err(FrameError::FeatureCount { got: 31, .. })),
        "{r:?}"
    );
    let mut nan = features;
    nan[30] = f32::NAN;
    let r = est.on_frame(&frame(4, true, 0.9, &nan), &mut emit);
    let err = r.expect_err("NaN is refused");
    assert!(err.to_string().contains("gaze_angle_x"), "{err}");
    let r = est.on_frame(&frame(5, true, 0.9, &features), &mut emit);
    assert!(matches!(r, Ok(FrameOutcome::Classified(_))));
    est.flush(&mut emit);
    assert_eq!(out.len(), 1);
    assert_eq!(
        (out[0].frame_count(), out[0].missing_frames),
        (1, 3),
        "errors are not counted"
    );
}

#[test]
fn a_synthetic_session_matches_the_offline_per_second_computation() {
    // 2 cameras, 30 fps, 20 s of SYNTHETIC frames; seconds computed offline from the labels.
    let table = generate(&SyntheticSpec {
        participants: 2,
        frames_per_participant: 600,
        ..Default::default()
    });
    let mut est = estimator();
    let mut online = Vec::new();
    let mut labels = vec![Vec::new(); 2];
    for k in 0..600 {
        for cam in 0..2u32 {
            let i = cam as usize * 600 + k;
            let raw = &table.rows[i];
            let f32_row: Vec<f32> = engagement_classifier::features::OPENFACE_FEATURES
                .iter()
                .enumerate()
                .map(|(c, _)| raw[c] as f32)
                .collect();
            let t = (k as i64) * S / 30 + i64::from(cam) * 1_000_000;
            let frame = FaceFrame {
                stamp_ns: t,
                source: cam,
                detection_success: true,
                confidence: 0.98,
                features: &f32_row,
            };
            match est
                .on_frame(&frame, &mut |s| online.push(*s))
                .expect("valid frame")
            {
                FrameOutcome::Classified(p) => labels[cam as usize].push((t / S, p.label)),
                FrameOutcome::Missing(_) => unreachable!("all frames have a face"),
            }
        }
    }
    est.flush(&mut |s| online.push(*s));
    assert_eq!(online.len(), 40);
    for cam in 0..2u32 {
        let means: Vec<f64> = (0..20)
            .map(|sec| {
                let l: Vec<f64> = labels[cam as usize]
                    .iter()
                    .filter(|(s, _)| *s == sec)
                    .map(|(_, l)| f64::from(*l))
                    .collect();
                l.iter().sum::<f64>() / l.len() as f64
            })
            .collect();
        let smoothed = smooth_series(&means, 0.75, true);
        let ours: Vec<&EngagementSecond> = online.iter().filter(|s| s.source == cam).collect();
        for (sec, s) in ours.iter().enumerate() {
            assert_eq!(s.frame_count(), 30);
            assert!((s.engagement.expect("face") - means[sec]).abs() < 1e-12);
            assert!((s.smoothed_engagement.expect("face") - smoothed[sec]).abs() < 1e-12);
        }
    }
}

/// `ros2 param set` while running: the params take a change of the writable keys only (checked
/// as at start-up), and the estimator applies a new `min_confidence` from the next frame.
#[test]
fn a_min_confidence_change_applies_from_the_next_frame() {
    let mut params = EngagementClassifierParams::default();
    let mut est = estimator();
    let mut emit = |_: &EngagementSecond| {};
    let features = [0.5f32; 32];
    let frame = |t| FaceFrame {
        stamp_ns: t,
        source: 0,
        detection_success: true,
        confidence: 0.6,
        features: &features,
    };
    let r = est.on_frame(&frame(0), &mut emit);
    assert_eq!(r, Ok(FrameOutcome::Missing(MissingReason::LowConfidence)));

    let changed = EngagementClassifierParams {
        min_confidence: 0.5,
        ..params.clone()
    };
    params.change(changed).expect("a writable key");
    est.set_min_confidence(params.min_confidence);
    let r = est.on_frame(&frame(1), &mut emit);
    assert!(matches!(r, Ok(FrameOutcome::Classified(_))), "{r:?}");

    // Out of range: refused as at start-up, nothing changed.
    let bad = EngagementClassifierParams {
        min_confidence: 1.5,
        ..params.clone()
    };
    let e = params.change(bad).expect_err("out of range");
    assert!(e.contains("min_confidence"), "{e}");
    assert_eq!(params.min_confidence, 0.5);
    // Thresholds out of order: refused.
    let bad = EngagementClassifierParams {
        ros4hri_engaged_threshold: -0.8,
        ..params.clone()
    };
    let e = params.change(bad).expect_err("disengaged above engaged");
    assert!(e.contains("ros4hri_disengaged_threshold"), "{e}");
    // A read-only key: refused.
    let bad = EngagementClassifierParams {
        smoothing_alpha: 0.5,
        ..params.clone()
    };
    let e = params.change(bad).expect_err("read-only");
    assert!(e.contains("only min_confidence"), "{e}");
}
