//! `behaviour_policy show-q-table <file>`: a Q-table file in words: whose it is, where it came
//! from, and per state its Q-values, greedy action, visits and temperature.

use anyhow::Context;
use q_learning::learning::{allowed_count, greedy_set, nth_member};
use q_learning::{QTableFile, TemperatureSchedule};
use sequence_game::{Action, State};
use std::path::PathBuf;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// A Q-table file (e.g. out/q_tables/cluster_0.json).
    file: PathBuf,
    /// Also list states never updated (all Q-values 0).
    #[arg(long)]
    all: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let file = QTableFile::load(&a.file).with_context(|| "show-q-table".to_string())?;
    let schedule = TemperatureSchedule::default();
    let mut out = String::new();
    use std::fmt::Write as _;
    writeln!(
        out,
        "{}: {}, {} live updates\nprovenance: {}\n",
        a.file.display(),
        file.owner,
        file.updates,
        file.provenance
    )?;
    writeln!(
        out,
        "{:<20} {:>8} {:>8} {:>8} {:>8} {:>8}  {:<14} {:>6} {:>6}",
        "state (L, F, PS)", "a1", "a2", "a3", "a4", "a5", "greedy", "visits", "T_s"
    )?;
    let mut hidden = 0;
    for state in State::all() {
        let q = file.table.q[state.index()];
        if !a.all && q.iter().all(|v| *v == 0.0) {
            hidden += 1;
            continue;
        }
        let allowed = allowed_count(state);
        let (set, n) = greedy_set(&q, allowed);
        let greedy = if n == 1 {
            Action::ALL[nth_member(set, 0)].name().to_string()
        } else {
            format!("{n}-way tie")
        };
        let cells: Vec<String> = (0..q.len())
            .map(|i| {
                if i < allowed {
                    format!("{:>8.3}", q[i])
                } else {
                    format!("{:>8}", "-")
                }
            })
            .collect();
        let visits = file.table.visits[state.index()];
        writeln!(
            out,
            "{:<20} {}  {:<14} {:>6} {:>6.1}",
            state.to_string(),
            cells.join(" "),
            greedy,
            visits,
            schedule.at(visits)
        )?;
    }
    if hidden > 0 {
        writeln!(out, "({hidden} states never updated; --all lists them)")?;
    }
    writeln!(
        out,
        "T_s with the default schedule max(0.5, 300 - 5 visits); a4/a5 are not allowed in the start state"
    )?;
    // A closed pipe (`| head`) is not an error worth a panic.
    use std::io::Write as _;
    match std::io::stdout().lock().write_all(out.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => Ok(r?),
    }
}
