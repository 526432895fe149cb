//! `tablet_tls` (installed as `qt-therapy-tls`), the program the package runs at install and
//! upgrade: it makes the robot's CA and server certificate once and keeps them, makes a new
//! server certificate (same CA) for a new name or before the old one runs out, refuses a name
//! its CA may not sign, keeps the keys private, and prints and exports the CA.

use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, SystemTime};
use tablet_bridge::certificates::{self, InitOptions, Name};

fn tool(dir: &Path, args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_tablet_tls"))
        .arg("--dir")
        .arg(dir)
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .env("RUST_LIB_BACKTRACE", "0")
        .output()
        .expect("tablet_tls runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr),
    )
}

fn read(dir: &Path, name: &str) -> Vec<u8> {
    std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn mode(dir: &Path, name: &str) -> u32 {
    std::fs::metadata(dir.join(name))
        .expect("metadata")
        .permissions()
        .mode()
        & 0o777
}

#[test]
fn init_makes_the_ca_once_and_keeps_what_is_still_good() {
    let tmp = tempfile::tempdir().expect("dir");
    let dir = tmp.path().join("tls");
    let (ok, out) = tool(
        &dir,
        &[
            "init",
            "--only-names",
            "--name",
            "qtrobot.test",
            "--name",
            "192.168.5.20",
        ],
    );
    assert!(ok, "{out}");
    assert!(
        out.contains("made a new CA") && out.contains("made a server certificate"),
        "{out}"
    );
    assert_eq!(
        (mode(&dir, "ca.key"), mode(&dir, "server.key")),
        (0o600, 0o600)
    );
    assert_eq!(
        (mode(&dir, "ca.crt"), mode(&dir, "server.crt")),
        (0o644, 0o644)
    );
    let ca = read(&dir, "ca.crt");
    let server = read(&dir, "server.crt");
    let key = read(&dir, "server.key");

    // The fingerprint printed is the CA's SHA-256, as `fingerprint` prints it alone.
    let (ok, fp) = tool(&dir, &["fingerprint"]);
    assert!(ok, "{fp}");
    let fp = fp.trim().to_string();
    assert_eq!(
        fp,
        certificates::fingerprint(&certificates::read_ca(&dir).expect("CA"))
    );
    assert_eq!(fp.len(), 32 * 3 - 1, "{fp}");
    assert!(
        out.contains(&format!("CA SHA-256 fingerprint: {fp}")),
        "{out}"
    );

    // Again (an upgrade): nothing changes.
    let (ok, again) = tool(
        &dir,
        &[
            "init",
            "--only-names",
            "--name",
            "qtrobot.test",
            "--name",
            "192.168.5.20",
        ],
    );
    assert!(
        ok && again.contains("kept the CA") && again.contains("kept the server certificate"),
        "{again}"
    );
    assert_eq!(
        (
            read(&dir, "ca.crt"),
            read(&dir, "server.crt"),
            read(&dir, "server.key")
        ),
        (ca.clone(), server.clone(), key.clone())
    );

    // The robot got another address: a new server certificate by the same CA.
    let (ok, moved) = tool(
        &dir,
        &[
            "init",
            "--only-names",
            "--name",
            "qtrobot.test",
            "--name",
            "10.1.2.3",
        ],
    );
    assert!(ok && moved.contains("kept the CA"), "{moved}");
    assert!(
        moved.contains("made a server certificate (not good for 10.1.2.3"),
        "{moved}"
    );
    assert_eq!(read(&dir, "ca.crt"), ca);
    assert_ne!(read(&dir, "server.crt"), server);
    let chain = tablet_bridge::tls::read_certificates(&dir.join("server.crt")).expect("chain");
    let names = [
        Name::Dns("qtrobot.test".into()),
        Name::parse("10.1.2.3").expect("ip"),
    ];
    let ca_der = certificates::read_ca(&dir).expect("CA");
    assert!(certificates::verify_server(&ca_der, &chain, &names, SystemTime::now()).is_ok());
    assert!(
        tablet_bridge::tls::server_config(&dir.join("server.crt"), &dir.join("server.key")).is_ok()
    );

    // A public name the CA was not made for: refused, naming it, nothing written.
    let before = read(&dir, "server.crt");
    let (ok, refused) = tool(
        &dir,
        &[
            "init",
            "--only-names",
            "--name",
            "qtrobot.example.org",
            "--name",
            "10.1.2.3",
        ],
    );
    assert!(!ok, "{refused}");
    assert!(
        refused.contains("may not sign qtrobot.example.org") && refused.contains("--new-ca"),
        "{refused}"
    );
    assert_eq!(read(&dir, "server.crt"), before);

    // export-ca writes the CA as it is, for the tablets.
    let file = tmp.path().join("qtrobot-ca.crt");
    let (ok, exported) = tool(&dir, &["export-ca", file.to_str().expect("utf-8")]);
    assert!(ok && exported.contains(&fp), "{exported}");
    assert_eq!(std::fs::read(&file).expect("exported"), ca);

    // --new-ca: a new CA and so a new server certificate.
    let (ok, new) = tool(
        &dir,
        &["init", "--new-ca", "--only-names", "--name", "qtrobot.test"],
    );
    assert!(
        ok && new.contains("made a new CA") && !new.contains(&fp),
        "{new}"
    );
    assert_ne!(read(&dir, "ca.crt"), ca);
}

#[test]
fn by_default_the_certificate_names_this_computer() {
    let tmp = tempfile::tempdir().expect("dir");
    let (ok, out) = tool(tmp.path(), &["init"]);
    assert!(ok, "{out}");
    let host = nix::unistd::gethostname().expect("host name");
    let host = host.to_string_lossy().to_ascii_lowercase();
    let names = out
        .lines()
        .find_map(|l| l.trim().strip_prefix("for "))
        .unwrap_or_else(|| panic!("no names in {out}"));
    for wanted in ["localhost", "127.0.0.1", "::1", host.as_str()] {
        assert!(
            names.split(", ").any(|n| n == wanted),
            "{wanted} not in {names}"
        );
    }
}

#[test]
fn a_server_certificate_is_made_anew_before_it_runs_out_and_keeps_its_keys_owner() {
    let tmp = tempfile::tempdir().expect("dir");
    let dir = tmp.path().to_path_buf();
    let names = vec![Name::Dns("qtrobot.test".into())];
    let now = SystemTime::now();
    let options = |now, key_owner| InitOptions {
        dir: dir.clone(),
        names: names.clone(),
        new_ca: false,
        key_owner,
        now,
    };
    // Made 780 days ago: 800-day certificates have 20 days left, under the 30 kept.
    let root = nix::unistd::Uid::effective().is_root();
    let owner = root.then_some((65534, 65534));
    let old = options(now - Duration::from_secs(780 * 86_400), owner);
    let made = certificates::init(&old).expect("made long ago");
    assert!(made.ca_made && made.server_made.is_some());
    let ca = read(&dir, "ca.crt");
    let server = read(&dir, "server.crt");
    // 770 days ago it would have been kept.
    let kept =
        certificates::init(&options(now - Duration::from_secs(770 * 86_400), None)).expect("kept");
    assert_eq!(kept.server_made, None);
    let renewed = certificates::init(&options(now, None)).expect("renewed");
    let why = renewed.server_made.expect("a new server certificate");
    assert!(why.contains("in 30 days"), "{why}");
    assert!(!renewed.ca_made);
    assert_eq!(read(&dir, "ca.crt"), ca);
    assert_ne!(read(&dir, "server.crt"), server);
    if root {
        // The new key belongs to whoever owned the old one (the service user), still 0600.
        let meta = std::fs::metadata(dir.join("server.key")).expect("key");
        assert_eq!((meta.uid(), meta.gid()), (65534, 65534));
        assert_eq!(meta.permissions().mode() & 0o777, 0o600);
    }
    // Without the CA's key the good certificate is kept, and a new one is refused saying why.
    std::fs::remove_file(dir.join("ca.key")).expect("rm");
    assert!(certificates::init(&options(now, None)).is_ok());
    let more = InitOptions {
        names: vec![
            Name::Dns("qtrobot.test".into()),
            Name::parse("10.0.0.9").expect("ip"),
        ],
        ..options(now, None)
    };
    let e = certificates::init(&more)
        .expect_err("no CA key")
        .to_string();
    assert!(e.contains("no ca.key"), "{e}");
}
