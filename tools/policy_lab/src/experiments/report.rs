//! The experiments' outputs in words and numbers: every curve as CSV (one row per configuration
//! and epoch), and the last-epoch table.

use crate::experiments::grid::Curve;
use q_learning::training::EpochMetrics;

/// Every curve: config, cluster, reward, mode, transfer_from, epoch, then mean and std of each
/// metric (score, engagement, ratio, return, v, explored).
pub fn curves_csv(curves: &[Curve]) -> Result<Vec<u8>, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header: Vec<String> = [
        "config",
        "cluster",
        "reward",
        "mode",
        "transfer_from",
        "epoch",
    ]
    .map(String::from)
    .to_vec();
    for name in EpochMetrics::NAMES {
        header.push(format!("{name}_mean"));
        header.push(format!("{name}_std"));
    }
    w.write_record(&header)?;
    for c in curves {
        for (e, (m, s)) in c.mean.iter().zip(&c.std).enumerate() {
            let mut row = vec![
                c.config.name.clone(),
                c.config.cluster.to_string(),
                c.config.reward.name().to_string(),
                format!("{:?}", c.config.mode),
                c.config
                    .transfer_from
                    .map(|k| k.to_string())
                    .unwrap_or_default(),
                (e + 1).to_string(),
            ];
            for (a, b) in m.values().iter().zip(s.values()) {
                row.push(format!("{a:.6}"));
                row.push(format!("{b:.6}"));
            }
            w.write_record(&row)?;
        }
    }
    w.into_inner().map_err(|e| csv::Error::from(e.into_error()))
}

/// The first epoch at which the mean score (5-epoch moving average) has covered `fraction` of
/// its way from the first epoch to the mean of the last 10: a plain reading of "converged
/// after N epochs". `None` for a curve that moves less than one point.
pub fn rise_epoch(curve: &Curve, fraction: f64) -> Option<usize> {
    let scores: Vec<f64> = curve.mean.iter().map(|e| e.score).collect();
    let n = scores.len();
    let first = *scores.first()?;
    let w = n.min(10);
    let last = scores[n - w..].iter().sum::<f64>() / w as f64;
    if (last - first).abs() < 1.0 {
        return None;
    }
    let goal = first + fraction * (last - first);
    (0..n)
        .find(|&e| {
            let window = &scores[e.saturating_sub(2)..(e + 3).min(n)];
            let smooth = window.iter().sum::<f64>() / window.len() as f64;
            (smooth - goal) * (last - first).signum() >= 0.0
        })
        .map(|e| e + 1)
}

/// The last epoch of every curve, aligned for a terminal.
pub fn last_epoch_table(curves: &[Curve]) -> String {
    let mut out = format!(
        "{:<24} {:>15} {:>7} {:>15} {:>8} {:>8} {:>8}\n",
        "configuration", "score", "ratio", "engagement", "return", "V", "90% at"
    );
    for c in curves {
        let (Some(m), Some(s)) = (c.mean.last(), c.std.last()) else {
            continue;
        };
        let settled = rise_epoch(c, 0.9).map_or("flat".to_string(), |e| e.to_string());
        out.push_str(&format!(
            "{:<24} {:>7.2} ± {:<5.2} {:>7.3} {:>7.3} ± {:<5.3} {:>8.2} {:>8.2} {:>8}\n",
            c.config.name,
            m.score,
            s.score,
            m.ratio,
            m.engagement,
            s.engagement,
            m.discounted_return,
            m.start_value,
            settled
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiments::grid::Config;
    use q_learning::learning::{Mode, Reward};

    fn curve(scores: &[f64]) -> Curve {
        let mean: Vec<EpochMetrics> = scores
            .iter()
            .map(|&score| EpochMetrics {
                score,
                ..Default::default()
            })
            .collect();
        Curve {
            config: Config {
                name: "M1->M2 RE+bE exploit".into(),
                cluster: 1,
                reward: Reward::RePlusBetaE,
                mode: Mode::Exploit,
                transfer_from: Some(0),
            },
            std: mean.clone(),
            mean,
            best_run: 0,
            best_return: 0.0,
        }
    }

    #[test]
    fn csv_has_a_row_per_epoch_and_every_metric() {
        let bytes = curves_csv(&[curve(&[1.0, 2.5])]).expect("csv");
        let text = String::from_utf8(bytes).expect("utf8");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        assert!(lines[0].starts_with("config,cluster,reward,mode,transfer_from,epoch,score_mean"));
        assert_eq!(lines[0].split(',').count(), 18);
        assert!(lines[2].starts_with("M1->M2 RE+bE exploit,1,RE+bE,Exploit,0,2,2.500000"));
    }

    #[test]
    fn rise_epoch_is_where_the_smoothed_curve_covers_most_of_its_way() {
        let mut scores = vec![0.0, 0.0, 0.0, 0.0, 0.0, 10.0, 10.0, 10.0, 10.0, 10.0];
        scores.extend([10.0; 10]);
        // Moving averages from epoch 1: 0, 0, 0, 2, 4, 6, 8, 10 ... so 90% (9.0) at epoch 8.
        assert_eq!(rise_epoch(&curve(&scores), 0.9), Some(8));
        let falling: Vec<f64> = scores.iter().map(|s| -s).collect();
        assert_eq!(rise_epoch(&curve(&falling), 0.9), Some(8));
        assert_eq!(rise_epoch(&curve(&[5.0, 5.3, 4.9, 5.2]), 0.9), None);
        assert_eq!(rise_epoch(&curve(&[]), 0.9), None);
    }
}
