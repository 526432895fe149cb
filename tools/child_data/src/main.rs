//! `child_data` (installed as `qt-therapy-data`): a child's data on the robot, for a parent
//! who asks for it or for it to be deleted.
//!   qt-therapy-data list   --user child-7               # what the suite holds, what erase would do
//!   qt-therapy-data export --user child-7 --output child-7.tar.gz
//!   qt-therapy-data erase  --user child-7               # asks to confirm at a terminal; --yes
//!
//! Exit status: 0 done; 1 an error (named); 2 a wrong command line; erase only: 3 done, but
//! something still holds data of this user (listed: fitted models, a report about someone
//! else too, a file it cannot tell apart, a place it could not read); 4 refused, nothing
//! changed (a session of this user running, a run still writing, a damaged bag, no
//! confirmation).

use anyhow::Context;
use child_data::erase::{EXIT_REFUSED, erase};
use child_data::export::{default_output, export, outside_notes};
use child_data::{Inventory, UserId};
use clap::{Args, Parser, Subcommand};
use std::io::{BufRead, IsTerminal, Write};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "qt-therapy-data",
    about = "List, export or erase everything the therapy suite holds for one user id",
    after_help = "Exit status: 0 done; 1 an error; 2 a wrong command line; erase: 3 done, but \
                  something still holds data of this user (listed), 4 refused, nothing changed."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// What the suite holds of the user, where, and what erase would do with each file.
    List(Where),
    /// One .tar.gz with everything of the user and a MANIFEST.txt saying what each file is.
    Export {
        #[command(flatten)]
        at: Where,
        /// The archive to write [default: ./child-data-<id>.tar.gz]; never overwritten.
        #[arg(long)]
        output: Option<PathBuf>,
    },
    /// Deletes or rewrites everything of the user (bags included), and says what it changed.
    Erase {
        #[command(flatten)]
        at: Where,
        /// Rewrite a damaged bag from what reads before the damage, without this user's
        /// messages; the unreadable rest of it is lost.
        #[arg(long)]
        rewrite_damaged: bool,
        /// Do not ask: erase at once (for scripts, after `list`).
        #[arg(long)]
        yes: bool,
    },
}

#[derive(Args)]
struct Where {
    /// The user id, exactly as the therapist gave it at the session's start.
    #[arg(long)]
    user: String,
    /// A directory the suite keeps data in (bags, session files, q_tables/, logs); may be
    /// given more than once.
    #[arg(
        long = "data",
        value_name = "DIR",
        default_value = "/var/lib/qt-therapy"
    )]
    data: Vec<PathBuf>,
    /// More files or directories to search (reports, CSVs, fitted models kept elsewhere).
    #[arg(value_name = "PATH")]
    paths: Vec<PathBuf>,
}

impl Where {
    fn inventory(&self) -> anyhow::Result<Inventory> {
        let user = UserId::new(&self.user)?;
        let mut places = self.data.clone();
        places.extend(self.paths.iter().cloned());
        Inventory::build(&user, &places).context("searching for the user's data")
    }
}

fn main() {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::exit(1);
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<i32> {
    match cli.command {
        Command::List(at) => {
            let inv = at.inventory()?;
            print!("{}", inv.to_text());
            for n in outside_notes(&inv) {
                println!("note: {n}");
            }
            Ok(0)
        }
        Command::Export { at, output } => {
            let inv = at.inventory()?;
            let output = output.unwrap_or_else(|| default_output(&inv));
            let done = export(&inv, &output)
                .with_context(|| format!("exporting into {}", output.display()))?;
            print!("{}", done.manifest);
            println!(
                "\nwrote {} ({} files and MANIFEST.txt); it holds the child's data: hand it \
                 over, then delete it",
                done.archive.display(),
                done.entries.len()
            );
            if let Ok(archive) = std::fs::canonicalize(&done.archive)
                && inv.places.iter().any(|p| archive.starts_with(p))
            {
                println!(
                    "note: the archive is inside a place searched; a later erase of this user \
                     will not open it"
                );
            }
            Ok(0)
        }
        Command::Erase {
            at,
            rewrite_damaged,
            yes,
        } => {
            let inv = at.inventory()?;
            if inv.items.is_empty() && inv.refusals(rewrite_damaged).is_empty() {
                print!("{}", inv.to_text());
                println!("nothing to erase");
                // A place that could not be read may still hold data of the user.
                return Ok(if inv.unreadable.is_empty() {
                    0
                } else {
                    child_data::erase::EXIT_STILL_HELD
                });
            }
            if inv.refusals(rewrite_damaged).is_empty() && !yes && !confirmed(&inv)? {
                eprintln!("not confirmed: nothing was changed");
                return Ok(EXIT_REFUSED);
            }
            let (outcome, erased) = erase(&inv, rewrite_damaged);
            for line in &erased.changed {
                println!("{line}");
            }
            for line in &erased.left {
                println!("STILL HOLDS DATA OF THIS USER: {line}");
            }
            for line in &erased.problems {
                eprintln!(
                    "{}: {line}",
                    match outcome {
                        child_data::erase::Outcome::Refused => "refused",
                        _ => "error",
                    }
                );
            }
            for n in &erased.notes {
                println!("note: {n}");
            }
            Ok(outcome.exit_code())
        }
    }
}

/// Shows what erase will do and asks for the user id again at a terminal.
fn confirmed(inv: &Inventory) -> anyhow::Result<bool> {
    if !std::io::stdin().is_terminal() {
        eprintln!(
            "erase deletes for good: run it at a terminal to confirm, or add --yes (after \
             checking `list`)"
        );
        return Ok(false);
    }
    print!("{}", inv.to_text());
    print!("To erase all of this, type the user id again: ");
    std::io::stdout().flush()?;
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line)?;
    Ok(line.trim_end_matches(['\n', '\r']) == inv.user.as_str())
}
