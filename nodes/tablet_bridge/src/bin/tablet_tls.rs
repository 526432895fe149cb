//! `tablet_tls` (installed as `qt-therapy-tls`): the robot's own certificates for the tablet
//! pages. `init` makes a CA of the robot's own and a server certificate for this computer's
//! names (keeping what is still good), `fingerprint` prints the CA's SHA-256 fingerprint, and
//! `export-ca` writes the CA file to install on the tablets (docs/install.md).
//!   sudo qt-therapy-tls init --key-owner qt-therapy
//!   qt-therapy-tls export-ca qtrobot-ca.crt

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use tablet_bridge::certificates::{
    self, CA_CERT, CA_KEY, InitOptions, Name, SERVER_CERT, SERVER_KEY,
};

#[derive(Parser)]
#[command(about = "The robot's own CA and server certificate for the tablet pages (HTTPS)")]
struct Cli {
    /// The certificates' directory.
    #[arg(
        long,
        global = true,
        env = "QT_TLS_DIR",
        default_value = "/etc/qt-therapy/tls"
    )]
    dir: PathBuf,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Make the CA (ca.crt, ca.key) unless there is one, and a server certificate (server.crt,
    /// server.key) unless the one there covers every name for 30 more days; print the CA's
    /// fingerprint. Run again after the robot's address or name changed.
    Init {
        /// A host name or address the tablets use (repeat); added to this computer's own
        /// (host name, <host>.local, localhost, its IPv4 addresses, ::1).
        #[arg(long = "name")]
        names: Vec<String>,
        /// Only the --name names, not this computer's own.
        #[arg(long)]
        only_names: bool,
        /// Replace the CA (and so the server certificate): every tablet must install the new
        /// CA. Needed only when the old key is lost or leaked, or the CA may not sign a new name.
        #[arg(long)]
        new_ca: bool,
        /// The user (and their group) who owns a new server.key: the bridge's (qt-therapy
        /// for the service). Default: the old key's owner, else whoever runs this.
        #[arg(long)]
        key_owner: Option<String>,
    },
    /// Print the SHA-256 fingerprint of the CA, as the tablets show it when it is installed.
    Fingerprint,
    /// Write the CA's certificate (PEM) to FILE to install on the tablets; print its fingerprint.
    ExportCa { file: PathBuf },
}

fn main() -> anyhow::Result<()> {
    // packaging/deb/build.sh asks each program for its manual pages.
    man_pages::write_if_asked::<Cli>();
    let cli = Cli::parse();
    match cli.command {
        Command::Init {
            names,
            only_names,
            new_ca,
            key_owner,
        } => {
            let mut all = if only_names {
                Vec::new()
            } else {
                certificates::default_names()
            };
            for n in &names {
                all.push(Name::parse(n).context("--name")?);
            }
            all.sort();
            all.dedup();
            let key_owner = key_owner.map(|u| owner(&u)).transpose()?;
            let made = certificates::init(&InitOptions {
                dir: cli.dir.clone(),
                names: all,
                new_ca,
                key_owner,
                now: std::time::SystemTime::now(),
            })?;
            let dir = cli.dir.display();
            if made.ca_made {
                println!(
                    "made a new CA: {dir}/{CA_CERT} ({dir}/{CA_KEY}: keep it on this computer)"
                );
                println!(
                    "  every tablet must install it: qt-therapy-tls export-ca FILE (docs/install.md)"
                );
            } else {
                println!("kept the CA: {dir}/{CA_CERT}");
            }
            match &made.server_made {
                Some(why) => println!(
                    "made a server certificate ({why}): {dir}/{SERVER_CERT}, {dir}/{SERVER_KEY}"
                ),
                None => println!("kept the server certificate: {dir}/{SERVER_CERT}"),
            }
            let names: Vec<String> = made.names.iter().map(Name::to_string).collect();
            println!("  for {}", names.join(", "));
            println!("CA SHA-256 fingerprint: {}", made.fingerprint);
        }
        Command::Fingerprint => {
            let ca = certificates::read_ca(&cli.dir)?;
            println!("{}", certificates::fingerprint(&ca));
        }
        Command::ExportCa { file } => {
            let ca = certificates::read_ca(&cli.dir)?;
            let pem = std::fs::read(cli.dir.join(CA_CERT))
                .with_context(|| format!("reading {}", cli.dir.join(CA_CERT).display()))?;
            certificates::write_file(&file, &pem, 0o644, None)?;
            println!(
                "wrote {} (install it on each tablet: docs/install.md)",
                file.display()
            );
            println!("CA SHA-256 fingerprint: {}", certificates::fingerprint(&ca));
        }
    }
    Ok(())
}

/// uid and gid of `user` (`user` or `user:group`).
fn owner(spec: &str) -> anyhow::Result<(u32, u32)> {
    let (user, group) = match spec.split_once(':') {
        Some((u, g)) => (u, Some(g)),
        None => (spec, None),
    };
    let u = nix::unistd::User::from_name(user)
        .with_context(|| format!("looking up user {user:?}"))?
        .with_context(|| format!("--key-owner: no user {user:?} on this computer"))?;
    let gid = match group {
        None => u.gid.as_raw(),
        Some(g) => nix::unistd::Group::from_name(g)
            .with_context(|| format!("looking up group {g:?}"))?
            .with_context(|| format!("--key-owner: no group {g:?} on this computer"))?
            .gid
            .as_raw(),
    };
    Ok((u.uid.as_raw(), gid))
}
