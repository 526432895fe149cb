//! `session_report`: a recorded session (MCAP bag) → one HTML page with its figures; or, with
//! `--user`, one child's progress across every session stored under the sessions root.
//!   session_report out/session/session.mcap --output out/session/report.html
//!   qt-therapy-report          (installed: the last run's bag under /var/lib/qt-therapy/sessions)
//!   qt-therapy-report --user child-7 [--language de]     (./progress-child-7.html)

use anyhow::Context;
use child_sessions::{Language, Progress, UserId, progress_document};
use clap::Parser;
use session_report::{SessionLog, last_bag, report_html};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(
    about = "Write the HTML report of a session recorded in a bag, or of a child's progress \
             across sessions (--user)"
)]
struct Cli {
    /// The bag (.mcap) the session was recorded in [default: the newest `session.mcap` in
    /// the runs under --sessions-root].
    #[arg(conflicts_with = "user")]
    bag: Option<PathBuf>,
    /// A child's progress across every session stored under --sessions-root (the session
    /// files, and the bags of their runs) instead: the user id (the child's code) exactly as
    /// given at the session's start. One self-contained HTML file that prints on A4.
    #[arg(long, value_name = "ID")]
    user: Option<String>,
    /// The progress report's language: en or de.
    #[arg(long, default_value = "en", requires = "user")]
    language: String,
    /// Where the installed service records its runs (one directory each).
    #[arg(
        long,
        env = "QT_THERAPY_SESSIONS",
        default_value = "/var/lib/qt-therapy/sessions"
    )]
    sessions_root: PathBuf,
    /// Where to write the report [default: report.html beside the bag, or
    /// report-<run>.html here when that directory is not writable; with --user,
    /// progress-<id>.html here].
    #[arg(long)]
    output: Option<PathBuf>,
    /// Which session, if the bag holds several [default: the last one].
    #[arg(long, conflicts_with = "user")]
    session: Option<String>,
}

/// `--user`: the child's progress, from what is stored under the sessions root.
fn progress(cli: &Cli, user: &str) -> anyhow::Result<()> {
    let language = Language::from_code(&cli.language)
        .with_context(|| format!("--language {:?}: the report is in en or de", cli.language))?;
    let user = UserId::new(user)?;
    let progress = Progress::build(&user, std::slice::from_ref(&cli.sessions_root))
        .with_context(|| format!("reading the stored sessions of {:?}", user.as_str()))?;
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
    let html = progress_document(&progress, language, now);
    let output = cli
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("progress-{}.html", user.file_stem())));
    write(&output, &html)?;
    for problem in &progress.problems {
        eprintln!("warning: {problem}");
    }
    let n = progress.sessions.len();
    println!(
        "{}: {n} session{} under {}, progress report {}",
        user.as_str(),
        if n == 1 { "" } else { "s" },
        cli.sessions_root.display(),
        output.display()
    );
    Ok(())
}

fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let cli = Cli::parse();
    if let Some(user) = &cli.user {
        return progress(&cli, user);
    }
    let bag = match &cli.bag {
        Some(bag) => bag.clone(),
        None => {
            let bag = last_bag(&cli.sessions_root).with_context(|| {
                format!(
                    "no bag given, and none found under {} (--sessions-root)",
                    cli.sessions_root.display()
                )
            })?;
            println!("the last recorded run: {}", bag.display());
            bag
        }
    };
    let reader =
        bag_file::BagReader::open(&bag).with_context(|| format!("reading {}", bag.display()))?;
    if let Some(damage) = reader.damage() {
        eprintln!("warning: {damage}; reporting what was recorded before it");
    }
    let log = SessionLog::from_bag(&reader, cli.session.as_deref())
        .with_context(|| format!("decoding {}", bag.display()))?;
    let html =
        report_html(&log).with_context(|| format!("making the report of {}", bag.display()))?;
    let output = match cli.output {
        Some(output) => write(&output, &html)?,
        None => {
            let beside = bag.with_file_name("report.html");
            match atomic_file::write(&beside, html.as_bytes()) {
                Ok(()) => beside,
                // The service's state is the service's to write; a therapist's account reads it.
                Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
                    let run = bag
                        .parent()
                        .and_then(Path::file_name)
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or_else(|| "session".into());
                    let here = PathBuf::from(format!("report-{run}.html"));
                    eprintln!(
                        "{} is not writable here; the report goes to ./{}",
                        beside.display(),
                        here.display()
                    );
                    write(&here, &html)?
                }
                Err(e) => {
                    return Err(e).with_context(|| format!("writing {}", beside.display()));
                }
            }
        }
    };
    let s = log.summary()?;
    println!(
        "session {}: {} sequences, score {} of {}, report {}",
        s.session_id,
        s.tally.sequences,
        s.tally.score,
        s.tally.max_score,
        output.display()
    );
    if s.proposals.proposed > 0 {
        println!("{}", s.proposals.sentence());
    }
    Ok(())
}

fn write(output: &Path, html: &str) -> anyhow::Result<PathBuf> {
    atomic_file::write(output, html.as_bytes())
        .with_context(|| format!("writing {}", output.display()))?;
    Ok(output.to_path_buf())
}
