//! ROS4HRI (REP-155) over DDS, read the way ROS4HRI's own client library reads it. The real
//! classifier process is fed a camera's OpenFace frames; a listener that joins late subscribes
//! as libhri does and must get, for each person the classifier reports, what REP-155 requires
//! (`/humans/persons/<id>/anonymous`, latched) with the lists `/humans/persons/tracked` and
//! `/humans/persons/known` and the person's `engagement_status`; a session starting, the face
//! lost and the node stopping change the persons as documented. Every process runs in a
//! private loopback-only network namespace.

use engagement_classifier::ros4hri::ANONYMOUS_PREFIX;
use engagement_classifier::synthetic::{SyntheticSpec, generate};
use engagement_classifier::{EngagementClassifierParams, EngagementModel};
use node_shell::{NoParameters, NodeShell, ShellOptions, ros_name};
use qt_therapy_msgs::builtin_interfaces::Time;
use qt_therapy_msgs::hri_msgs::{EngagementLevel, IdsList};
use qt_therapy_msgs::std_msgs::{BoolMsg, Header};
use qt_therapy_msgs::topics::{
    self, PERSONS_KNOWN, PERSONS_TRACKED, engagement_status, person_anonymous,
};
use qt_therapy_msgs::{GameState, MessageDefinition, OpenFaceFeatures, dds_type_name};
use ros2_client::QosProfile;
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};

mod common;
use common::{classifier, workspace};

/// Set in the copy of the test that runs inside the network namespace.
const IN_NAMESPACE: &str = "ENGAGEMENT_CLASSIFIER_ROS4HRI_TEST_IN_LOOPBACK_NETNS";

/// The session's user, which no ROS4HRI id or topic may name.
const USER_ID: &str = "1CZ1CL1P";

/// What REP-155 requires of each person, received the libhri way by a late listener; each
/// person replaced when a session starts, dropped when its face is lost for the tracked
/// timeout, a face seen again a new person; the lists emptied when the node stops. Before
/// the classifier published `anonymous` and `known`, the listener never got them and this
/// failed at the first person.
#[test]
fn a_late_libhri_listener_gets_what_rep155_requires_of_each_person() {
    let Some(stdout) = loopback_netns::test_inside_namespace(
        "a_late_libhri_listener_gets_what_rep155_requires_of_each_person",
        IN_NAMESPACE,
        Duration::from_secs(120),
        inside_the_namespace,
    ) else {
        return;
    };
    assert!(stdout.contains("ROS4HRI over DDS:"), "{stdout}");
}

/// What the libhri-like listener has received.
#[derive(Debug, Default)]
struct Seen {
    tracked: Option<Vec<String>>,
    known: Option<Vec<String>>,
    /// Every id ever tracked, in order of appearance.
    persons: Vec<String>,
    anonymous: BTreeMap<String, Vec<bool>>,
    levels: BTreeMap<String, Vec<u8>>,
}

impl Seen {
    fn listed(&self, ids: &[&str]) -> bool {
        let want: Vec<String> = ids.iter().map(|s| s.to_string()).collect();
        self.tracked.as_ref() == Some(&want) && self.known.as_ref() == Some(&want)
    }
}

enum Event {
    Tracked(IdsList),
    Known(IdsList),
    Anonymous(String, bool),
    Level(String, u8),
}

/// ROS 2's `SystemDefaultsQoS()` under rmw_fastrtps and rmw_cyclonedds: the DDS reader
/// defaults, best effort, volatile, keep last 1.
fn system_default_qos() -> QosProfile {
    QosProfile::subscription_default()
        .reliability(Reliability::BestEffort)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 1 })
}

/// libhri's `latched_qos`: `SystemDefaultsQoS().transient_local().reliable()`.
fn latched_qos() -> QosProfile {
    system_default_qos()
        .reliability(Reliability::Reliable {
            when_full: WhenFull::DEFAULT,
        })
        .durability(Durability::TransientLocal)
}

/// Subscribes as libhri does, following ros4hri/libhri (branch humble-devel, 2.3.0):
/// `hri/src/hri/hri.cpp` (`HRIListener`) reads `/humans/persons/tracked` and
/// `/humans/persons/known` with `SystemDefaultsQoS` and, for each id newly listed, makes a
/// `Person`; `hri/src/hri/person.cpp` (`Person`'s constructor) then subscribes to the
/// person's `anonymous` with `latched_qos` and `engagement_status` with `default_qos`, and
/// drops them when the id leaves the list (`invalidate`). So a person's subscriptions are
/// always made after the classifier published `anonymous`: only a latched writer reaches them.
struct Libhri {
    events: mpsc::UnboundedSender<Event>,
    /// Per followed person, the tasks reading its topics.
    persons: BTreeMap<String, Vec<tokio::task::JoinHandle<()>>>,
}

impl Libhri {
    fn new(shell: &mut NodeShell) -> (Libhri, mpsc::UnboundedReceiver<Event>) {
        let (tx, rx) = mpsc::unbounded_channel();
        let mut l = Libhri {
            events: tx,
            persons: BTreeMap::new(),
        };
        for (name, known) in [(PERSONS_TRACKED.name, false), (PERSONS_KNOWN.name, true)] {
            let task = l.read::<IdsList>(shell, name, system_default_qos(), move |m| {
                if known {
                    Event::Known(m)
                } else {
                    Event::Tracked(m)
                }
            });
            drop(task); // read for the listener's life
        }
        (l, rx)
    }

    fn read<M: MessageDefinition>(
        &mut self,
        shell: &mut NodeShell,
        name: &str,
        qos: QosProfile,
        event: impl Fn(M) -> Event + Send + 'static,
    ) -> tokio::task::JoinHandle<()> {
        let node = shell.node_mut();
        let topic = node
            .create_topic(
                &ros_name(name).expect("ROS name"),
                dds_type_name::<M>(),
                &qos,
            )
            .expect("topic");
        let subscription = node
            .create_subscription::<M>(&topic, Some(qos))
            .expect("subscription");
        let tx = self.events.clone();
        tokio::spawn(async move {
            while let Ok((m, _)) = subscription.async_take().await {
                if tx.send(event(m)).is_err() {
                    break;
                }
            }
        })
    }

    /// A tracked list arrived: follow the new ids, drop the ones gone.
    fn on_tracked(&mut self, shell: &mut NodeShell, ids: &[String]) {
        self.persons.retain(|id, tasks| {
            let keep = ids.contains(id);
            if !keep {
                tasks.iter().for_each(|t| t.abort());
            }
            keep
        });
        for id in ids {
            if self.persons.contains_key(id) {
                continue;
            }
            let (a, e) = (id.clone(), id.clone());
            let tasks = vec![
                self.read::<BoolMsg>(shell, person_anonymous(id).name, latched_qos(), move |m| {
                    Event::Anonymous(a.clone(), m.data)
                }),
                self.read::<EngagementLevel>(
                    shell,
                    engagement_status(id).name,
                    system_default_qos(),
                    move |m| Event::Level(e.clone(), m.level),
                ),
            ];
            self.persons.insert(id.clone(), tasks);
        }
    }
}

/// Takes the listener's events into `seen` until `done(seen)` or `limit`; panics then.
async fn until(
    what: &str,
    limit: Duration,
    shell: &mut NodeShell,
    listener: &mut Libhri,
    events: &mut mpsc::UnboundedReceiver<Event>,
    seen: &mut Seen,
    done: impl Fn(&Seen) -> bool,
) -> Duration {
    let started = Instant::now();
    while !done(seen) {
        let left = limit.saturating_sub(started.elapsed());
        let Ok(Some(event)) = tokio::time::timeout(left, events.recv()).await else {
            panic!("{what}: not within {limit:?}; the listener saw {seen:#?}");
        };
        match event {
            Event::Tracked(l) => {
                listener.on_tracked(shell, &l.ids);
                for id in &l.ids {
                    if !seen.persons.contains(id) {
                        seen.persons.push(id.clone());
                    }
                }
                seen.tracked = Some(l.ids);
            }
            Event::Known(l) => seen.known = Some(l.ids),
            Event::Anonymous(id, v) => seen.anonymous.entry(id).or_default().push(v),
            Event::Level(id, l) => seen.levels.entry(id).or_default().push(l),
        }
    }
    started.elapsed()
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Camera {
    Face,
    NoFace,
    Off,
}

fn inside_the_namespace() {
    let params_file = workspace().join("params/engagement_classifier.yaml");
    let params = EngagementClassifierParams::from_yaml_file(&params_file).expect("params");
    let model = EngagementModel::load(&workspace().join(&params.model_file)).expect("model");
    // Frames the model calls engaged, so each second with a face is ENGAGED.
    let engaged: Vec<Vec<f32>> = generate(&SyntheticSpec {
        participants: 1,
        frames_per_participant: 300,
        label_noise: 0.0,
        seed: 11,
        ..Default::default()
    })
    .rows
    .iter()
    .map(|r| r.map(|v| v as f32))
    .filter(|f| model.predict_f32(f).label == 1)
    .map(|f| f.to_vec())
    .collect();
    assert!(engaged.len() > 50, "engaged frames to send");

    let dir = tempfile::tempdir().expect("temp dir");
    let probe_params = dir.path().join("probe.yaml");
    std::fs::write(&probe_params, "ros4hri_probe:\n  ros__parameters: {}\n").expect("writes");
    let mut node = classifier(
        &params_file,
        dir.path(),
        &["ros4hri_tracked_timeout_s:=2.0"],
    );

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let report = runtime.block_on(async {
        let options = ShellOptions {
            params_file: Some(probe_params.clone()),
            namespace: "/".into(),
            service_mapping: "enhanced".into(),
            ..Default::default()
        };
        let (mut shell, NoParameters {}) =
            NodeShell::start("ros4hri_probe", &options).expect("probe node");
        let features = shell
            .publisher(topics::OPENFACE_FEATURES)
            .expect("publisher");
        // The game manager's state (QosKind::State, published on every change).
        let states = shell.publisher(topics::GAME_STATE).expect("publisher");
        let mut seconds = shell
            .subscribe(topics::EXPECTED_ENGAGEMENT, 256)
            .expect("reader");
        assert!(
            features
                .wait_for_subscribers(&shell, Duration::from_secs(30))
                .await,
            "the classifier never subscribed to the frames"
        );
        // One camera at 10 frames a second, stamped with the clock as the OpenFace bridge does.
        let (camera, mode) = watch::channel(Camera::Face);
        let sender = tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_millis(100));
            let mut k = 0usize;
            loop {
                tick.tick().await;
                let m = *mode.borrow();
                if m == Camera::Off {
                    break;
                }
                features.send(OpenFaceFeatures {
                    header: Header {
                        stamp: Time::from_nanos(node_shell::now_nanos()),
                        frame_id: "cam_front".into(),
                    },
                    face_id: "0".into(),
                    confidence: if m == Camera::Face { 0.98 } else { 0.0 },
                    success: m == Camera::Face,
                    features: engaged[k % engaged.len()].clone(),
                });
                k += 1;
            }
        });

        // The first second with a face: the classifier has made the person and published
        // `anonymous` (and the lists) by now. Only then does the listener join.
        let deadline = Duration::from_secs(20);
        let started = Instant::now();
        loop {
            let left = deadline.saturating_sub(started.elapsed());
            match tokio::time::timeout(left, seconds.recv()).await {
                Ok(Some(s)) if s.has_faces => break,
                Ok(Some(_)) => {}
                _ => panic!("no second with a face within {deadline:?}"),
            }
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
        let (mut listener, mut events) = Libhri::new(&mut shell);
        let mut seen = Seen::default();
        let limit = Duration::from_secs(15);

        // 1. No session: the face is an anonymous person, listed in both lists, `anonymous`
        // true from the writer's history, its levels ENGAGED.
        let first = until(
            "the first person, late",
            limit,
            &mut shell,
            &mut listener,
            &mut events,
            &mut seen,
            |s| {
                s.persons.len() == 1
                    && s.listed(&[&s.persons[0]])
                    && s.anonymous.get(&s.persons[0]) == Some(&vec![true])
            },
        )
        .await;
        let a = seen.persons[0].clone();
        until(
            "the first person's levels",
            limit,
            &mut shell,
            &mut listener,
            &mut events,
            &mut seen,
            |s| s.levels.get(&s.persons[0]).is_some_and(|l| l.len() >= 2),
        )
        .await;

        // 2. A session starts: the person ends, a new one takes its place.
        states.send(GameState {
            header: node_shell::header_now(),
            phase: GameState::SAYING_SEQUENCE,
            session_id: "ros4hri-dds-session".into(),
            user_id: USER_ID.into(),
            sequences_planned: 10,
            ..Default::default()
        });
        let replaced = until(
            "a new person for the session",
            limit,
            &mut shell,
            &mut listener,
            &mut events,
            &mut seen,
            |s| {
                s.persons.len() == 2
                    && s.listed(&[&s.persons[1]])
                    && s.anonymous.get(&s.persons[1]) == Some(&vec![true])
            },
        )
        .await;
        let b = seen.persons[1].clone();
        until(
            "the session's person's levels",
            limit,
            &mut shell,
            &mut listener,
            &mut events,
            &mut seen,
            |s| s.levels.contains_key(&s.persons[1]),
        )
        .await;

        // 3. The face is lost: UNKNOWN while within the timeout (2 s), then nobody listed.
        camera.send(Camera::NoFace).expect("camera");
        let lost = until(
            "the person gone once its face was lost",
            limit,
            &mut shell,
            &mut listener,
            &mut events,
            &mut seen,
            |s| s.listed(&[]),
        )
        .await;

        // 4. The face again: a new person; then the node stops and empties the lists.
        camera.send(Camera::Face).expect("camera");
        until(
            "a new person for the face seen again",
            limit,
            &mut shell,
            &mut listener,
            &mut events,
            &mut seen,
            |s| {
                s.persons.len() == 3
                    && s.listed(&[&s.persons[2]])
                    && s.anonymous.get(&s.persons[2]) == Some(&vec![true])
            },
        )
        .await;
        let c = seen.persons[2].clone();
        camera.send(Camera::Off).expect("camera");
        sender.await.expect("frame sender");
        node.interrupt();
        let emptied = until(
            "the lists emptied when the node stops",
            limit,
            &mut shell,
            &mut listener,
            &mut events,
            &mut seen,
            |s| s.listed(&[]),
        )
        .await;
        drop((states, seconds, listener, events));
        shell.stop().await;
        (seen, [a, b, c], [first, replaced, lost, emptied])
    });
    let (seen, [a, b, c], [first, replaced, lost, emptied]) = report;

    let status = node.wait_for_exit(Duration::from_secs(20));
    let log = std::fs::read_to_string(dir.path().join("node.err")).unwrap_or_default();
    assert!(
        status.is_some_and(|s| s.success()),
        "exit {status:?}\n{log}"
    );
    assert_eq!(seen.persons, [a.clone(), b.clone(), c.clone()], "{seen:#?}");
    for id in &seen.persons {
        assert!(
            id.starts_with(ANONYMOUS_PREFIX)
                && !id.to_lowercase().contains(&USER_ID.to_lowercase()),
            "{id}"
        );
        assert_eq!(seen.anonymous.get(id), Some(&vec![true]), "{id}");
    }
    use EngagementLevel as L;
    assert!(
        seen.levels[&a].iter().all(|l| *l == L::ENGAGED),
        "{seen:#?}"
    );
    assert!(seen.levels[&b].contains(&L::ENGAGED), "{seen:#?}");
    assert!(
        seen.levels[&b].contains(&L::UNKNOWN),
        "a second without the face, before the person ended: {seen:#?}"
    );
    println!(
        "ROS4HRI over DDS: a libhri-style listener joining late had the first person {a} in \
         both lists with anonymous=true {first:.1?} after it subscribed; the session's person \
         {b} replaced it {replaced:.1?} after the session's state was sent; {b} left both \
         lists {lost:.1?} after its face was lost (timeout 2 s); {c} for the face seen \
         again; both lists empty {emptied:.1?} after SIGINT; levels {:?}",
        seen.levels
    );
}
