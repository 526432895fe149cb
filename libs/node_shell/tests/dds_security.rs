//! DDS Security end to end (only built with `--features security`): a keystore made by
//! security/make_keystore.sh, a secured game-manager subscriber on the therapist command
//! and engagement topics, and publishers that are authorised (tablet bridge enclave),
//! unauthenticated (no security), authenticated without publish permission (classifier and
//! game-manager enclaves), and a real identity with permissions it granted itself (signed by a
//! CA of its own), beside the same grant signed by the real CA as a control. An insecure
//! control subscriber shows the unauthenticated publisher really publishes, so its silence at
//! the secured subscriber is the security's doing.
//! Each participant is its own process (this test binary in a role), all inside one private
//! loopback-only network namespace (tests/loopback-netns).

use node_shell::{NoParameters, NodeShell, ShellOptions};
use qt_therapy_msgs::topics::{ENGAGEMENT_ESTIMATE, THERAPIST_COMMAND};
use qt_therapy_msgs::{EngagementEstimate, TherapistCommand};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

const IN_NAMESPACE: &str = "QT_DDS_SECURITY_TEST_IN_NAMESPACE";
const ROLE: &str = "QT_DDS_SECURITY_TEST_ROLE";
const SECURITY_VARS: [&str; 4] = [
    "ROS_SECURITY_ENABLE",
    "ROS_SECURITY_STRATEGY",
    "ROS_SECURITY_KEYSTORE",
    "ROS_SECURITY_ENCLAVE_OVERRIDE",
];
/// How long subscribers listen and publishers publish (secured discovery and the
/// authentication handshake happen inside this window).
const LISTEN: Duration = Duration::from_secs(30);
const PUBLISH: Duration = Duration::from_secs(25);

use loopback_netns::workspace_root;

/// Runs the test `name` of this binary again inside a private loopback-only namespace (where
/// it calls `inside`), or, when this process is a participant, plays its role. Returns the
/// namespace run's stdout, or None where namespaces cannot be made or inside.
fn in_loopback_namespace(name: &str, inside: fn()) -> Option<String> {
    if let Ok(role) = std::env::var(ROLE) {
        run_role(&role);
        return None;
    }
    if std::env::var_os(IN_NAMESPACE).is_some() {
        inside();
        return None;
    }
    let out = loopback_netns::rerun_test_inside(
        name,
        &[(IN_NAMESPACE, name.as_ref())],
        Duration::from_secs(180),
    )?;
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stdout}");
    assert!(out.status.success(), "{stdout}\n{stderr}");
    Some(stdout)
}

fn test_filter(name: &str) -> [&str; 5] {
    [
        "--exact",
        name,
        "--include-ignored",
        "--nocapture",
        "--test-threads=1",
    ]
}

/// Runs security/make_keystore.sh into `dir/keystore` with the given payload protection.
fn make_keystore(dir: &Path, data_protection: &str) -> PathBuf {
    let keystore = dir.join("keystore");
    let made = Command::new("bash")
        .arg(workspace_root().join("security/make_keystore.sh"))
        .arg(&keystore)
        .env("DATA_PROTECTION_KIND", data_protection)
        .output()
        .expect("runs security/make_keystore.sh");
    assert!(
        made.status.success(),
        "make_keystore.sh failed: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    keystore
}

/// Makes enclave `made` in `keystore`: the identity of `from` (its certificate, from the real
/// identity CA, and its key) with `from`'s permissions less their deny rule, so every topic
/// may be published. `forged`: signed, like its governance, by a permissions CA of its own,
/// which the enclave names as its permissions CA; its own DDS then lets it write anything,
/// and only the other participants' check of its permissions against the real permissions CA
/// can stop it (someone holding a node's key but not the permissions CA's). Not `forged`: signed
/// by the keystore's real permissions CA, the control that shows the same grant, properly
/// signed, is delivered.
fn grant_everything(keystore: &Path, from: &str, made: &str, forged: bool) {
    let enclaves = keystore.join("enclaves");
    let source = enclaves.join(from.trim_start_matches('/'));
    let dir = enclaves.join(made.trim_start_matches('/'));
    std::fs::create_dir_all(&dir).expect("enclave dir");
    for file in [
        "cert.pem",
        "key.pem",
        "identity_ca.cert.pem",
        "governance.p7s",
    ] {
        std::fs::copy(source.join(file), dir.join(file)).expect("copies the identity");
    }
    let permissions = std::fs::read_to_string(source.join("permissions.xml")).expect("reads");
    let (before, rest) = permissions.split_once("<deny_rule>").expect("a deny rule");
    let (_, after) = rest.split_once("</deny_rule>").expect("its end");
    std::fs::write(dir.join("permissions.xml"), format!("{before}{after}")).expect("writes");
    let openssl = |args: &[&str]| {
        let out = Command::new("openssl")
            .args(args)
            .current_dir(&dir)
            .output()
            .expect("runs openssl");
        assert!(
            out.status.success(),
            "openssl {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let path = |p: PathBuf| p.to_str().expect("utf-8 path").to_string();
    let (ca_cert, ca_key) = if forged {
        openssl(&[
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:prime256v1",
            "-nodes",
            "-sha256",
            "-days",
            "30",
            "-keyout",
            "forged_ca.key.pem",
            "-out",
            "permissions_ca.cert.pem",
            "-subj",
            "/CN=qt_therapy_permissions_ca",
        ]);
        (
            "permissions_ca.cert.pem".to_string(),
            "forged_ca.key.pem".to_string(),
        )
    } else {
        std::fs::copy(
            source.join("permissions_ca.cert.pem"),
            dir.join("permissions_ca.cert.pem"),
        )
        .expect("copies the permissions CA");
        (
            path(keystore.join("public/permissions_ca.cert.pem")),
            path(keystore.join("private/permissions_ca.key.pem")),
        )
    };
    let governance = path(enclaves.join("governance.xml"));
    let mut signed = vec![("permissions.xml", "permissions.p7s")];
    if forged {
        signed.push((&governance, "governance.p7s"));
    }
    for (input, output) in signed {
        openssl(&[
            "smime", "-sign", "-text", "-in", input, "-out", output, "-signer", &ca_cert, "-inkey",
            &ca_key,
        ]);
    }
}

#[test]
fn only_the_tablet_bridge_enclave_delivers_therapist_commands() {
    let name = "only_the_tablet_bridge_enclave_delivers_therapist_commands";
    if let Some(stdout) = in_loopback_namespace(name, commands_inside_the_namespace) {
        assert!(stdout.contains("DDS SECURITY CHECKED"), "{stdout}");
    }
}

/// What fails in RustDDS 0.15.1 itself, without ros2-client or node_shell: with
/// `data_protection_kind` ENCRYPT, a sample whose serialized payload is 20 bytes arrives and
/// one of 17 bytes never does (the DATA submessage pads the encoded payload to 4 bytes and
/// the decoder takes the padding as part of the crypto footer). This is why
/// make_keystore.sh defaults to payload protection NONE under submessage ENCRYPT. Ignored
/// (30 s); when it fails, RustDDS has been fixed and the governance can go back to ENCRYPT.
#[test]
#[ignore = "documents a RustDDS 0.15.1 bug; run with --ignored"]
fn rustdds_payload_encryption_loses_samples_of_unaligned_length() {
    let name = "rustdds_payload_encryption_loses_samples_of_unaligned_length";
    if let Some(stdout) = in_loopback_namespace(name, unaligned_inside_the_namespace) {
        assert!(stdout.contains("RUSTDDS BUG PRESENT"), "{stdout}");
    }
}

/// The hang seen once in CI (the authorised publisher stuck, RustDDS logging "I need my
/// lock!! ... tokio-rt-worker has it"), reproduced with RustDDS alone: in a secured
/// participant, `create_datareader` / `create_datawriter` take the security-plugins lock and,
/// while holding it, `dp.domain_id()` takes the participant lock (the guard is the method
/// call's receiver, so it is alive while the arguments are evaluated), whereas
/// `DomainParticipant::create_topic` holds the participant lock and then takes the plugins
/// lock. One thread creating readers while another creates topics deadlocks. In our nodes
/// the two threads were ros2-client's spinner (its two readers, on a tokio worker) and the
/// node's own start-up (topics): `NodeShell::start` now creates the spinner's readers on the
/// calling thread (see `shell.rs`). Ignored (up to 30 s); when it fails, RustDDS is fixed.
#[test]
#[ignore = "documents a RustDDS 0.15.1 deadlock; run with --ignored"]
fn rustdds_deadlocks_creating_readers_and_topics_at_once() {
    let name = "rustdds_deadlocks_creating_readers_and_topics_at_once";
    if let Some(stdout) = in_loopback_namespace(name, lock_order_inside_the_namespace) {
        assert!(stdout.contains("RUSTDDS DEADLOCK"), "{stdout}");
    }
}

fn lock_order_inside_the_namespace() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let keystore = make_keystore(d, "NONE");
    let racer = spawn(
        d,
        "racer",
        "raw_race",
        Some((keystore.as_path(), "/qt_therapy/game_manager")),
    );
    let out = finish(racer, d);
    println!("{out}");
}

/// One participant of a scenario.
struct Participant {
    label: &'static str,
    child: Child,
    log: PathBuf,
}

fn spawn(
    dir: &Path,
    label: &'static str,
    role: &str,
    keystore: Option<(&Path, &str)>,
) -> Participant {
    let params = dir.join(format!("{label}.yaml"));
    std::fs::write(&params, format!("{label}:\n  ros__parameters: {{}}\n")).expect("params");
    let log = dir.join(format!("{label}.log"));
    let test = std::env::var(IN_NAMESPACE).expect("runs inside the namespace");
    let mut command = Command::new(std::env::current_exe().expect("test binary"));
    command
        .args(test_filter(&test))
        .env(ROLE, role)
        .env("QT_TEST_NODE_NAME", label)
        .env("QT_TEST_PARAMS", &params)
        .env_remove(IN_NAMESPACE)
        .stdout(std::fs::File::create(&log).expect("log"))
        .stderr(std::fs::File::create(dir.join(format!("{label}.err"))).expect("log"));
    for var in SECURITY_VARS {
        command.env_remove(var);
    }
    if let Some((keystore, enclave)) = keystore {
        command
            .env("ROS_SECURITY_ENABLE", "true")
            .env("ROS_SECURITY_STRATEGY", "Enforce")
            .env("ROS_SECURITY_KEYSTORE", keystore)
            .env("ROS_SECURITY_ENCLAVE_OVERRIDE", enclave);
    }
    Participant {
        label,
        child: command.spawn().expect("starts a participant"),
        log,
    }
}

/// Waits for a participant and returns its stdout; prints the tail of its stderr.
fn finish(mut p: Participant, dir: &Path) -> String {
    let started = Instant::now();
    while p.child.try_wait().expect("wait").is_none() {
        if started.elapsed() > LISTEN + Duration::from_secs(40) {
            let _ = p.child.kill();
            let _ = p.child.wait();
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let out = std::fs::read_to_string(&p.log).unwrap_or_default();
    let err = std::fs::read_to_string(dir.join(format!("{}.err", p.label))).unwrap_or_default();
    let tail: Vec<&str> = err.lines().rev().take(5).collect();
    println!(
        "--- {} stderr (last lines) ---\n{}",
        p.label,
        tail.into_iter().rev().collect::<Vec<_>>().join("\n")
    );
    out
}

/// Counts per sender that a subscriber printed as `<marker> <sender> <count>` (`RECEIVED` for
/// commands, `ENGAGEMENT_RECEIVED` for engagement estimates).
fn received(out: &str, marker: &str) -> BTreeMap<String, u64> {
    out.lines()
        .filter_map(|l| {
            // libtest's "test ... " may precede a marker on its line.
            let mut words = l.split_whitespace().skip_while(|w| *w != marker).skip(1);
            let tag = words.next()?;
            Some((tag.to_string(), words.next()?.parse().ok()?))
        })
        .collect()
}

/// What a publisher said about itself: `ENGAGEMENT ...`, `SENT n` or `REFUSED ...`.
fn publisher_status(out: &str) -> Vec<&str> {
    out.lines()
        .filter_map(|l| {
            ["ENGAGEMENT ", "SENT ", "REFUSED "]
                .iter()
                .find_map(|marker| l.find(marker))
                .map(|at| &l[at..])
        })
        .collect()
}

fn commands_inside_the_namespace() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let keystore = make_keystore(d, "NONE");
    let ks = keystore.as_path();
    grant_everything(ks, "/qt_therapy/game_manager", "/qt_therapy/forged", true);
    grant_everything(
        ks,
        "/qt_therapy/game_manager",
        "/qt_therapy/regranted",
        false,
    );
    let secured_sub = spawn(
        d,
        "secured_game_manager",
        "subscribe",
        Some((ks, "/qt_therapy/game_manager")),
    );
    let control_sub = spawn(d, "insecure_control", "subscribe", None);
    std::thread::sleep(Duration::from_secs(1));
    let publishers = [
        spawn(
            d,
            "authorised",
            "publish",
            Some((ks, "/qt_therapy/tablet_bridge")),
        ),
        spawn(d, "unauthenticated", "publish", None),
        spawn(
            d,
            "classifier",
            "publish",
            Some((ks, "/qt_therapy/engagement_classifier")),
        ),
        spawn(
            d,
            "game_manager_writer",
            "publish",
            Some((ks, "/qt_therapy/game_manager")),
        ),
        spawn(d, "forged", "publish", Some((ks, "/qt_therapy/forged"))),
        spawn(
            d,
            "regranted",
            "publish",
            Some((ks, "/qt_therapy/regranted")),
        ),
    ];
    let mut status = BTreeMap::new();
    for p in publishers {
        let label = p.label;
        let out = finish(p, d);
        status.insert(label, publisher_status(&out).join("; "));
    }
    let secured_out = finish(secured_sub, d);
    let control_out = finish(control_sub, d);
    let secured = received(&secured_out, "RECEIVED");
    let control = received(&control_out, "RECEIVED");
    let secured_engagement = received(&secured_out, "ENGAGEMENT_RECEIVED");
    let control_engagement = received(&control_out, "ENGAGEMENT_RECEIVED");
    for (label, said) in &status {
        println!("publisher {label}: {said}");
    }
    println!("secured subscriber received: {secured:?}, engagement {secured_engagement:?}");
    println!(
        "insecure control subscriber received: {control:?}, engagement {control_engagement:?}"
    );

    // (a) the authorised, secured publisher reaches the secured subscriber.
    assert!(
        secured.get("authorised").copied().unwrap_or(0) > 0,
        "the tablet_bridge enclave delivered no command: {secured:?}"
    );
    // (b) the unauthenticated publisher does publish (the insecure control hears it) but
    // reaches no secured subscriber.
    assert!(
        control.get("unauthenticated").copied().unwrap_or(0) > 0,
        "the unauthenticated publisher did not publish at all: {control:?}"
    );
    assert_eq!(secured.get("unauthenticated"), None, "{secured:?}");
    // (c) authenticated participants without publish permission deliver nothing: their own
    // access control refuses the writer.
    for label in ["classifier", "game_manager_writer"] {
        assert_eq!(secured.get(label), None, "{secured:?}");
        assert!(
            status[label].contains("REFUSED publisher")
                && status[label].contains("not allowed by security"),
            "{label}: {}",
            status[label]
        );
    }
    // Engagement: only the classifier's enclave may create the writer.
    assert!(
        status["classifier"].contains("ENGAGEMENT allowed"),
        "{}",
        status["classifier"]
    );
    for label in ["authorised", "game_manager_writer"] {
        assert!(
            status[label].contains("ENGAGEMENT refused")
                && status[label].contains("not allowed by security"),
            "{label}: {}",
            status[label]
        );
    }
    // (d) the game manager's identity with permissions granting every topic, signed by a CA
    // of its own: its DDS lets it write commands and engagement, and it sends, but the secured
    // subscriber checks those permissions against the real permissions CA and takes nothing
    // from it. The same grant signed by the real CA is delivered: the signature made the
    // difference.
    for label in ["forged", "regranted"] {
        assert!(
            status[label].contains("ENGAGEMENT allowed") && status[label].contains("SENT "),
            "{label} was refused locally, so the remote check was not tested: {}",
            status[label]
        );
    }
    assert_eq!(secured.get("forged"), None, "{secured:?}");
    assert!(
        secured.get("regranted").copied().unwrap_or(0) > 0,
        "the control grant, signed by the real CA, delivered nothing: {secured:?}"
    );
    // Engagement, the same way: the classifier's and the control grant's estimates arrive, the
    // forged grant's and the unauthenticated publisher's do not (the latter's reach the
    // insecure control).
    for label in ["classifier", "regranted"] {
        assert!(
            secured_engagement.get(label).copied().unwrap_or(0) > 0,
            "{label} delivered no engagement: {secured_engagement:?}"
        );
    }
    for label in ["forged", "unauthenticated"] {
        assert_eq!(
            secured_engagement.get(label),
            None,
            "{secured_engagement:?}"
        );
    }
    assert!(
        control_engagement
            .get("unauthenticated")
            .copied()
            .unwrap_or(0)
            > 0,
        "{control_engagement:?}"
    );
    // The insecure control hears nothing from secured writers.
    assert_eq!(control.get("authorised"), None, "{control:?}");
    println!("DDS SECURITY CHECKED");
}

fn unaligned_inside_the_namespace() {
    let dir = tempfile::tempdir().expect("temp dir");
    let d = dir.path();
    let keystore = make_keystore(d, "ENCRYPT");
    let ks = keystore.as_path();
    let sub = spawn(
        d,
        "raw_sub",
        "raw_subscribe",
        Some((ks, "/qt_therapy/game_manager")),
    );
    std::thread::sleep(Duration::from_secs(1));
    // Serialized payload: 4 (encapsulation) + 4 (id) + 4 (string length) + name and NUL,
    // so "aligned" makes 20 bytes and "unaligned" 22.
    let aligned = spawn(
        d,
        "aligned",
        "raw_publish",
        Some((ks, "/qt_therapy/tablet_bridge")),
    );
    let unaligned = spawn(
        d,
        "unaligned",
        "raw_publish",
        Some((ks, "/qt_therapy/tablet_bridge")),
    );
    let sent_aligned = finish(aligned, d);
    let sent_unaligned = finish(unaligned, d);
    let got = received(&finish(sub, d), "RECEIVED");
    println!(
        "aligned: {:?}, unaligned: {:?}, received: {got:?}",
        publisher_status(&sent_aligned),
        publisher_status(&sent_unaligned)
    );
    assert!(got.get("aligned").copied().unwrap_or(0) > 0, "{got:?}");
    if !got.contains_key("unaligned") {
        println!("RUSTDDS BUG PRESENT: every unaligned sample lost");
    }
}

/// A participant process: `subscribe` counts commands per session id, `publish` sends a
/// PAUSE command tagged with its node name every 200 ms.
fn run_role(role: &str) {
    if let Some(raw) = role.strip_prefix("raw_") {
        raw_rustdds_role(raw);
        return;
    }
    let name = std::env::var("QT_TEST_NODE_NAME").expect("node name");
    let options = ShellOptions {
        params_file: Some(PathBuf::from(
            std::env::var("QT_TEST_PARAMS").expect("params"),
        )),
        namespace: "/".into(),
        service_mapping: "enhanced".into(),
        ..Default::default()
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let (mut shell, NoParameters {}) = match NodeShell::start(&name, &options) {
            Ok(s) => s,
            Err(e) => {
                println!("REFUSED participant: {e:#}");
                return;
            }
        };
        match role {
            "subscribe" => {
                let mut commands = shell.subscribe(THERAPIST_COMMAND, 1024).expect("subscribe");
                let mut engagement = shell
                    .subscribe(ENGAGEMENT_ESTIMATE, 1024)
                    .expect("subscribe");
                let mut counts: BTreeMap<String, u64> = BTreeMap::new();
                let mut engagement_counts: BTreeMap<String, u64> = BTreeMap::new();
                let deadline = tokio::time::sleep(LISTEN);
                tokio::pin!(deadline);
                loop {
                    tokio::select! {
                        _ = &mut deadline => break,
                        Some(command) = commands.recv() => {
                            *counts.entry(command.session_id).or_default() += 1;
                        }
                        Some(estimate) = engagement.recv() => {
                            *engagement_counts.entry(estimate.face_id).or_default() += 1;
                        }
                    }
                }
                for (tag, n) in &counts {
                    println!("RECEIVED {tag} {n}");
                }
                for (tag, n) in &engagement_counts {
                    println!("ENGAGEMENT_RECEIVED {tag} {n}");
                }
                drop((commands, engagement));
            }
            "publish" => {
                // Whether this enclave may write engagement estimates (only the classifier);
                // where it may, it sends them too, named by their face_id.
                let engagement = match shell.publisher(ENGAGEMENT_ESTIMATE) {
                    Ok(outbox) => {
                        println!("ENGAGEMENT allowed");
                        Some(outbox)
                    }
                    Err(e) => {
                        println!("ENGAGEMENT refused: {e:#}");
                        None
                    }
                };
                let outbox = match shell.publisher(THERAPIST_COMMAND) {
                    Ok(o) => Some(o),
                    Err(e) => {
                        println!("REFUSED publisher: {e:#}");
                        None
                    }
                };
                if engagement.is_none() && outbox.is_none() {
                    shell.stop().await;
                    return;
                }
                let started = tokio::time::Instant::now();
                let mut sent = 0u64;
                while started.elapsed() < PUBLISH {
                    if let Some(engagement) = &engagement {
                        engagement.send(EngagementEstimate {
                            header: node_shell::header_now(),
                            face_id: name.clone(),
                            label: EngagementEstimate::ENGAGED,
                            probability: 0.9,
                        });
                    }
                    let Some(outbox) = &outbox else {
                        tokio::time::sleep(Duration::from_millis(200)).await;
                        continue;
                    };
                    let ok = outbox.send(TherapistCommand {
                        header: node_shell::header_now(),
                        command: TherapistCommand::PAUSE,
                        session_id: name.clone(),
                        command_id: sent + 1,
                        user_id: String::new(),
                        user_model_cluster: -1,
                        level: 0,
                    });
                    if ok {
                        sent += 1;
                    }
                    tokio::time::sleep(Duration::from_millis(200)).await;
                }
                if outbox.is_some() {
                    println!("SENT {sent}");
                }
                drop((outbox, engagement));
            }
            other => panic!("unknown role {other}"),
        }
        shell.stop().await;
    });
}

/// The same exchange with RustDDS alone (no ros2-client, no node_shell): one NoKey CDR topic
/// carrying `RawCommand`, whose serialized length is 12 bytes plus the sender's name with its
/// NUL, so the name's length sets the payload's alignment.
fn raw_rustdds_role(role: &str) {
    use rustdds::policy::Reliability;
    use rustdds::{
        DomainParticipantBuilder, DomainParticipantSecurityConfigFiles, QosPolicyBuilder, TopicKind,
    };
    #[derive(serde::Serialize, serde::Deserialize)]
    struct RawCommand {
        id: i32,
        sender: String,
    }
    let name = std::env::var("QT_TEST_NODE_NAME").expect("node name");
    let mut builder = DomainParticipantBuilder::new(0);
    if let Ok(keystore) = std::env::var("ROS_SECURITY_KEYSTORE") {
        let enclave = std::env::var("ROS_SECURITY_ENCLAVE_OVERRIDE").expect("enclave");
        let dir = node_shell::security::enclave_dir(Path::new(&keystore), &enclave);
        builder = builder.builtin_security(
            DomainParticipantSecurityConfigFiles::with_ros_default_names(dir, String::new()),
        );
    }
    let participant = builder.build().expect("participant");
    if role == "race" {
        race_readers_against_topics(&participant);
        return;
    }
    let qos = QosPolicyBuilder::new()
        .reliability(Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .build();
    let topic = participant
        .create_topic(
            "rt/qt_therapy/therapist/command".to_string(),
            "qt_therapy::RawCommand".to_string(),
            &qos,
            TopicKind::NoKey,
        )
        .expect("topic");
    if role == "subscribe" {
        let mut reader = participant
            .create_subscriber(&qos)
            .expect("subscriber")
            .create_datareader_no_key_cdr::<RawCommand>(&topic, None)
            .expect("reader");
        let mut counts: BTreeMap<String, u64> = BTreeMap::new();
        let started = Instant::now();
        while started.elapsed() < LISTEN {
            while let Ok(Some(sample)) = reader.take_next_sample() {
                *counts.entry(sample.into_value().sender).or_default() += 1;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        for (tag, n) in &counts {
            println!("RECEIVED {tag} {n}");
        }
    } else {
        let writer = participant
            .create_publisher(&qos)
            .expect("publisher")
            .create_datawriter_no_key_cdr::<RawCommand>(&topic, None)
            .expect("writer");
        let started = Instant::now();
        let mut sent = 0;
        while started.elapsed() < PUBLISH {
            let sample = RawCommand {
                id: sent,
                sender: name.clone(),
            };
            if writer.write(sample, None).is_ok() {
                sent += 1;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        println!("SENT {sent}");
    }
}

/// One thread creates (and drops) readers on one topic while another creates new topics, for
/// 15 s; prints `RACE DONE` when both finish, or `RUSTDDS DEADLOCK` with how far each got
/// once neither has moved for 5 s (and exits, since the stuck threads cannot be joined).
fn race_readers_against_topics(participant: &rustdds::DomainParticipant) {
    use rustdds::{QosPolicyBuilder, TopicKind};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicU32, Ordering};
    const RACE: Duration = Duration::from_secs(15);
    let started = Instant::now();
    let qos = QosPolicyBuilder::new().build();
    let topic = participant
        .create_topic(
            "rt/qt_therapy/race/readers".to_string(),
            "qt_therapy::RawCommand".to_string(),
            &qos,
            TopicKind::NoKey,
        )
        .expect("topic");
    let subscriber = participant.create_subscriber(&qos).expect("subscriber");
    let (readers, topics) = (Arc::new(AtomicU32::new(0)), Arc::new(AtomicU32::new(0)));
    let reader_thread = {
        let readers = readers.clone();
        std::thread::spawn(move || {
            while started.elapsed() < RACE {
                let reader = subscriber.create_datareader_no_key_cdr::<u32>(&topic, None);
                drop(reader);
                readers.fetch_add(1, Ordering::Relaxed);
            }
        })
    };
    let topic_thread = {
        let (topics, participant) = (topics.clone(), participant.clone());
        std::thread::spawn(move || {
            for i in 0.. {
                if started.elapsed() >= RACE {
                    break;
                }
                let _ = participant.create_topic(
                    format!("rt/qt_therapy/race/topic_{i}"),
                    "qt_therapy::RawCommand".to_string(),
                    &qos,
                    TopicKind::NoKey,
                );
                topics.fetch_add(1, Ordering::Relaxed);
            }
        })
    };
    let mut last = (u32::MAX, u32::MAX);
    let mut still_since = Instant::now();
    loop {
        if reader_thread.is_finished() && topic_thread.is_finished() {
            println!(
                "RACE DONE: {} readers and {} topics in {RACE:?}",
                readers.load(Ordering::Relaxed),
                topics.load(Ordering::Relaxed)
            );
            return;
        }
        let now = (
            readers.load(Ordering::Relaxed),
            topics.load(Ordering::Relaxed),
        );
        if now != last {
            last = now;
            still_since = Instant::now();
        } else if still_since.elapsed() > Duration::from_secs(5) {
            println!(
                "RUSTDDS DEADLOCK: stuck after {} readers and {} topics, {:.1} s in",
                now.0,
                now.1,
                started.elapsed().as_secs_f64() - 5.0
            );
            std::process::exit(0);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}
