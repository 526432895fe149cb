//! Where the simulated users come from: a fitted user-model file (`user_model` crate), a JSON
//! list of tabulated `UserModelTable`s (what `experiments` writes beside its curves), or the
//! hand-made per-level reference tables, always named as what they are.

use anyhow::{Context, bail};
use q_learning::reference_tables::{PER_LEVEL_REFERENCE_NAME, per_level_reference_tables};
use sequence_game::UserModelTable;
use std::path::Path;

/// The clusters' tables and a phrase saying where they came from.
pub fn load(
    path: &Path,
    per_level_reference: bool,
) -> anyhow::Result<(Vec<UserModelTable>, String)> {
    if per_level_reference {
        return Ok((
            per_level_reference_tables(),
            PER_LEVEL_REFERENCE_NAME.into(),
        ));
    }
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading user models from {}", path.display()))?;
    // A JSON list is tabulated user models; anything else must be a user_model file.
    if text.trim_start().starts_with('[') {
        let tables: Vec<UserModelTable> = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a list of user-model tables", path.display()))?;
        for (i, t) in tables.iter().enumerate() {
            t.validate()
                .with_context(|| format!("{}, table [{i}]", path.display()))?;
        }
        if tables.is_empty() {
            bail!("{} lists no user-model tables", path.display());
        }
        let source = format!("tabulated user models from {}", path.display());
        check_order(&tables, &source)?;
        return Ok((tables, source));
    }
    let set = user_models::UserModelSet::load(path)
        .with_context(|| format!("loading user models from {}", path.display()))?;
    let source = format!("fitted user models {}", path.display());
    let tables = set.tables();
    check_order(&tables, &source)?;
    Ok((tables, source))
}

/// Row k of the list must be cluster k: the policy indexes clusters by position.
fn check_order(tables: &[UserModelTable], source: &str) -> anyhow::Result<()> {
    for (i, t) in tables.iter().enumerate() {
        if t.cluster != i {
            bail!(
                "{source}: table {i} is for cluster {}, expected {i}",
                t.cluster
            );
        }
    }
    Ok(())
}

/// The tables for the clusters asked for, refusing unknown ones by name.
pub fn check_clusters(
    tables: &[UserModelTable],
    clusters: &[usize],
    source: &str,
) -> anyhow::Result<()> {
    for &k in clusters {
        if k >= tables.len() {
            bail!(
                "unknown user model cluster {k}: {source} has {} cluster(s) (0..={})",
                tables.len(),
                tables.len().saturating_sub(1)
            );
        }
    }
    Ok(())
}

/// One line per cluster: P(success) and mean E per level, to tell the clusters apart.
pub fn describe(tables: &[UserModelTable]) -> String {
    use sequence_game::{Level, ModelInput};
    let mut out = String::new();
    for t in tables {
        out.push_str(&format!("  M{} (cluster {}):", t.cluster + 1, t.cluster));
        for level in Level::ALL {
            let inputs: Vec<ModelInput> = ModelInput::all().filter(|i| i.level == level).collect();
            let n = inputs.len() as f64;
            let p = inputs.iter().map(|&i| t.success(i).mean).sum::<f64>() / n;
            let e = inputs
                .iter()
                .flat_map(|&i| sequence_game::Outcome::ALL.map(|o| t.engagement(i, o).mean))
                .sum::<f64>()
                / (2.0 * n);
            out.push_str(&format!("  L{}: P {p:.3}, E {e:+.3}", level.get()));
        }
        out.push('\n');
    }
    out
}
