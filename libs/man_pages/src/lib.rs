//! Manual pages from a program's own clap definition, so a page never says other than `--help`.
//! Each program calls [`write_if_asked`] first thing in `main`; the package's build
//! (`packaging/deb/build.sh`) runs each built binary as
//! `PROGRAM --write-manpages DIR NAME DATE` and it writes `NAME.1` and, for each subcommand,
//! `NAME-SUB.1` (clap_mangen) into DIR and exits. NAME is the command as installed
//! (`qt-therapy-bag`), which differs from the binary's own name (`bag`). Any other command line
//! is left to the program's own parser; the flag is in no `--help`.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The first argument that asks for the pages.
pub const FLAG: &str = "--write-manpages";

/// The manual the pages belong to (the centre of a page's footer).
const MANUAL: &str = "QTrobot therapy suite";

/// Writes the program's manual pages and exits when its command line is
/// `FLAG DIR NAME DATE`; returns at once otherwise.
pub fn write_if_asked<C: clap::CommandFactory>() {
    let args: Vec<OsString> = std::env::args_os().skip(1).collect();
    if args.first().is_none_or(|a| a != FLAG) {
        return;
    }
    let code = match &args[1..] {
        [dir, name, date] => match (name.to_str(), date.to_str()) {
            (Some(name), Some(date)) => match write(C::command(), name, date, Path::new(dir)) {
                Ok(pages) => {
                    for p in pages {
                        println!("{}", p.display());
                    }
                    0
                }
                Err(e) => {
                    eprintln!(
                        "error: writing the manual pages into {}: {e}",
                        Path::new(dir).display()
                    );
                    1
                }
            },
            _ => {
                eprintln!("error: {FLAG}: NAME and DATE must be UTF-8");
                2
            }
        },
        _ => {
            eprintln!("usage: PROGRAM {FLAG} DIR NAME DATE   (DATE as YYYY-MM-DD)");
            2
        }
    };
    std::process::exit(code);
}

/// Renders `cmd` as the command `name` into `dir`: `name.1`, and `name-sub.1` for each
/// subcommand not hidden (recursively); returns the files written.
pub fn write(
    cmd: clap::Command,
    name: &str,
    date: &str,
    dir: &Path,
) -> std::io::Result<Vec<PathBuf>> {
    // The footer names the suite's version; a program without `version` keeps no `-V` (its
    // page shows the options it takes, no more).
    let source = format!(
        "qt-therapy {}",
        cmd.get_version().unwrap_or(env!("CARGO_PKG_VERSION"))
    );
    // clap keeps a command's name as `&'static str` (without its `string` feature, which
    // would rebuild clap for the whole workspace); the process ends right after.
    let static_name: &'static str = Box::leak(name.to_owned().into_boxed_str());
    // The installed name everywhere a page shows one (title, NAME, SYNOPSIS, the subcommands'
    // page names); clap's own help subcommand has no page of its own.
    let mut cmd = cmd
        .name(static_name)
        .bin_name(name)
        .display_name(name)
        .disable_help_subcommand(true);
    cmd.build();
    let mut written = Vec::new();
    render_tree(cmd, date, &source, dir, &mut written)?;
    Ok(written)
}

fn render_tree(
    cmd: clap::Command,
    date: &str,
    source: &str,
    dir: &Path,
    written: &mut Vec<PathBuf>,
) -> std::io::Result<()> {
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set()) {
        render_tree(sub.clone(), date, source, dir, written)?;
    }
    let page = clap_mangen::Man::new(cmd)
        .date(date)
        .source(source)
        .manual(MANUAL);
    written.push(page.generate_to(dir)?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Parser, Subcommand};

    /// A command line shaped like the suite's: a subcommand with its own options.
    #[derive(Parser)]
    #[command(
        name = "bag",
        about = "Record, play and inspect MCAP bags of the suite"
    )]
    struct Cli {
        #[command(subcommand)]
        command: Command,
    }

    #[derive(Subcommand)]
    enum Command {
        /// Record topics over DDS into an MCAP file until SIGINT/SIGTERM.
        Record {
            /// The bag to write.
            #[arg(long)]
            output: PathBuf,
        },
        #[command(hide = true)]
        Secret,
    }

    fn pages() -> (tempfile::TempDir, Vec<PathBuf>) {
        let dir = tempfile::tempdir().expect("temp dir");
        let pages = write(
            <Cli as clap::CommandFactory>::command(),
            "qt-therapy-bag",
            "2026-12-06",
            dir.path(),
        )
        .expect("pages written");
        (dir, pages)
    }

    #[test]
    fn one_page_per_command_and_visible_subcommand_under_the_installed_name() {
        let (dir, pages) = pages();
        let mut names: Vec<String> = pages
            .iter()
            .map(|p| {
                p.strip_prefix(dir.path())
                    .expect("in dir")
                    .display()
                    .to_string()
            })
            .collect();
        names.sort();
        assert_eq!(names, ["qt-therapy-bag-record.1", "qt-therapy-bag.1"]);
    }

    #[test]
    fn a_page_says_what_help_says() {
        let (dir, _) = pages();
        let top = std::fs::read_to_string(dir.path().join("qt-therapy-bag.1")).expect("page");
        assert!(
            top.contains(
                ".TH qt-therapy-bag 1 2026-12-06 \"qt-therapy 0.1.0\" \"QTrobot therapy suite\""
            ),
            "{top}"
        );
        assert!(
            top.contains("qt\\-therapy\\-bag \\- Record, play and inspect MCAP bags of the suite"),
            "{top}"
        );
        assert!(top.contains("qt\\-therapy\\-bag\\-record(1)"), "{top}");
        assert!(
            !top.contains("secret"),
            "a hidden subcommand is listed: {top}"
        );
        assert!(
            !top.contains("\\-\\-version"),
            "an option the program lacks: {top}"
        );
        let record =
            std::fs::read_to_string(dir.path().join("qt-therapy-bag-record.1")).expect("page");
        assert!(
            record.contains("Record topics over DDS into an MCAP file"),
            "{record}"
        );
        assert!(record.contains("\\-\\-output"), "{record}");
    }
}
