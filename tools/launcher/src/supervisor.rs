//! Runs the processes of a launch description: starts each with its output prefixed by its
//! name on the terminal, or in its log file (`output: log`), reports a process that dies,
//! respawns those marked `respawn`, and stops everything (SIGINT, then SIGKILL after a grace
//! period) on Ctrl-C, SIGTERM or an `on_exit: shutdown`. Under systemd's watchdog it feeds the
//! watchdog while every node it runs is alive (`crate::watchdog`).

use crate::watchdog::{self, Watchdog};
use launcher::description::ProcessSpec;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::collections::HashMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};
use tokio::signal::unix::{SignalKind, signal};
use tokio::sync::mpsc;

enum Event {
    Exited {
        name: String,
        code: Option<i32>,
        signal: Option<i32>,
    },
    Respawn(String),
}

/// How long the output of a process that exited is still read before its exit is reported.
const OUTPUT_DRAIN: Duration = Duration::from_secs(1);

fn say(text: &str) {
    eprintln!("[launch] {text}");
}

/// Where one process's lines go: the terminal (stdout lines to stdout, stderr lines to stderr),
/// its log file, or both.
#[derive(Clone)]
struct Sink {
    name: String,
    screen: bool,
    log: Option<Arc<Mutex<std::fs::File>>>,
}

impl Sink {
    fn open(spec: &ProcessSpec, log_dir: &Path) -> std::io::Result<Sink> {
        let log = if spec.output.to_log() {
            std::fs::create_dir_all(log_dir)?;
            let file = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(log_path(log_dir, &spec.name))?;
            Some(Arc::new(Mutex::new(file)))
        } else {
            None
        };
        Ok(Sink {
            name: spec.name.clone(),
            screen: spec.output.to_screen(),
            log,
        })
    }

    fn line(&self, line: &str, from_stderr: bool) {
        if self.screen {
            if from_stderr {
                eprintln!("[{}] {line}", self.name);
            } else {
                println!("[{}] {line}", self.name);
            }
        }
        if let Some(file) = &self.log
            && let Ok(mut f) = file.lock()
        {
            // A full disk must not stop the node: the line is lost, the node goes on.
            let _ = writeln!(f, "{line}");
        }
    }
}

/// The log file of the process `name`.
pub fn log_path(log_dir: &Path, name: &str) -> PathBuf {
    log_dir.join(format!("{name}.log"))
}

fn start(
    spec: &ProcessSpec,
    log_dir: &Path,
    events: mpsc::UnboundedSender<Event>,
) -> std::io::Result<u32> {
    let sink = Sink::open(spec, log_dir)?;
    let mut cmd = Command::new(&spec.program);
    cmd.args(&spec.args)
        .envs(spec.env.iter().cloned())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        // The watchdog is the launcher's to feed, not the nodes'.
        .env_remove(watchdog::ENVIRONMENT[0])
        .env_remove(watchdog::ENVIRONMENT[1])
        .env_remove(watchdog::ENVIRONMENT[2])
        // Own process group: a terminal's Ctrl-C reaches only us, and we stop the nodes in order.
        .process_group(0)
        .kill_on_drop(true);
    if let Some(cwd) = &spec.cwd {
        cmd.current_dir(cwd);
    }
    let mut child: Child = cmd.spawn()?;
    let pid = child.id().unwrap_or(0);
    let name = spec.name.clone();
    let mut forwarders = Vec::new();
    if let Some(out) = child.stdout.take() {
        forwarders.push(forward_lines(out, sink.clone(), false));
    }
    if let Some(err) = child.stderr.take() {
        forwarders.push(forward_lines(err, sink, true));
    }
    tokio::spawn(async move {
        let status = child.wait().await;
        // The exit can be seen before the last lines are read from the pipes; the launcher may
        // exit on this event, so forward them first. Bounded, because a grandchild that
        // inherited the pipes can keep them open after the node itself is gone.
        let _ = tokio::time::timeout(OUTPUT_DRAIN, async {
            for forwarder in forwarders {
                let _ = forwarder.await;
            }
        })
        .await;
        use std::os::unix::process::ExitStatusExt;
        let (code, signal) = match status {
            Ok(s) => (s.code(), s.signal()),
            Err(_) => (None, None),
        };
        let _ = events.send(Event::Exited { name, code, signal });
    });
    Ok(pid)
}

/// Passes each line of a node's output pipe to its sink until the pipe closes.
fn forward_lines<R>(pipe: R, sink: Sink, from_stderr: bool) -> tokio::task::JoinHandle<()>
where
    R: tokio::io::AsyncRead + Unpin + Send + 'static,
{
    tokio::spawn(async move {
        let mut lines = BufReader::new(pipe).lines();
        while let Ok(Some(line)) = lines.next_line().await {
            sink.line(&line, from_stderr);
        }
    })
}

fn describe(code: Option<i32>, signal: Option<i32>) -> String {
    match (code, signal) {
        (Some(c), _) => format!("exit code {c}"),
        (None, Some(s)) => format!(
            "signal {}",
            Signal::try_from(s)
                .map(|s| s.as_str().to_string())
                .unwrap_or_else(|_| s.to_string())
        ),
        _ => "unknown status".to_string(),
    }
}

/// Looks at the running nodes: feeds the watchdog when every one is alive, and says when that
/// changes (`frozen`: what was found not alive at the last look).
fn look_at_nodes(
    running: &HashMap<String, u32>,
    watchdog: &Watchdog,
    frozen: &mut Vec<String>,
    feed_failed: &mut bool,
) {
    let mut now: Vec<String> = running
        .iter()
        .filter_map(|(name, pid)| {
            watchdog::not_alive(*pid).map(|why| format!("{name} (pid {pid}) is {why}"))
        })
        .collect();
    now.sort();
    if now.is_empty() {
        match watchdog.feed() {
            Ok(()) => *feed_failed = false,
            Err(e) if !*feed_failed => {
                say(&format!("could not feed systemd's watchdog: {e}"));
                *feed_failed = true;
            }
            Err(_) => {}
        }
    }
    if now != *frozen {
        if now.is_empty() {
            say("every node is alive again: feeding systemd's watchdog");
        } else {
            say(&format!(
                "{}: not feeding systemd's watchdog; if this lasts {:?}, systemd restarts \
                 the service",
                now.join(", "),
                watchdog.timeout
            ));
        }
        *frozen = now;
    }
}

/// Runs `specs` to the end, the logs of those with `output: log` or `both` in `log_dir`;
/// returns the launcher's exit code. With `watchdog`, feeds it while every node is alive.
pub async fn run(
    specs: Vec<ProcessSpec>,
    grace: Duration,
    log_dir: &Path,
    watchdog: Option<Watchdog>,
) -> anyhow::Result<i32> {
    let logged: Vec<&str> = specs
        .iter()
        .filter(|s| s.output.to_log())
        .map(|s| s.name.as_str())
        .collect();
    if !logged.is_empty() {
        say(&format!(
            "output of {} in {}/<name>.log",
            logged.join(", "),
            log_dir.display()
        ));
    }
    let (tx, mut rx) = mpsc::unbounded_channel();
    let by_name: HashMap<String, ProcessSpec> =
        specs.iter().map(|s| (s.name.clone(), s.clone())).collect();
    let mut running: HashMap<String, u32> = HashMap::new();
    let mut restarts: HashMap<String, u32> = HashMap::new();
    let mut failed = false;
    // Our handlers before any node starts: a Ctrl-C during start-up stops the nodes instead of
    // killing the launcher alone, and the nodes start with SIGINT and SIGTERM at their default
    // (a handled signal resets on exec, an ignored one would not: a launcher started from a
    // script's background job ignores SIGINT, and so then did every node that is not ours).
    let mut interrupt = signal(SignalKind::interrupt())?;
    let mut terminate = signal(SignalKind::terminate())?;
    for spec in &specs {
        match start(spec, log_dir, tx.clone()) {
            Ok(pid) => {
                say(&format!(
                    "started {} (pid {pid}): {} {}",
                    spec.name,
                    spec.program,
                    spec.args.join(" ")
                ));
                running.insert(spec.name.clone(), pid);
            }
            Err(e) => {
                say(&format!(
                    "could not start {} ({}): {e}",
                    spec.name, spec.program
                ));
                failed = true;
            }
        }
    }
    if failed {
        stop_all(&mut running, &mut rx, grace).await;
        return Ok(1);
    }
    let mut exit_code = 0;
    // The looks run in this loop, so a launcher stuck anywhere in it stops feeding too.
    let mut look = watchdog.as_ref().map(|w| {
        say(&format!(
            "feeding systemd's watchdog (WatchdogSec {:?}) while every node is alive",
            w.timeout
        ));
        tokio::time::interval(w.look_every())
    });
    let mut frozen = Vec::new();
    let mut feed_failed = false;
    loop {
        if running.is_empty() && !by_name.values().any(|s| s.respawn) {
            break;
        }
        let event = tokio::select! {
            _ = interrupt.recv() => { say("Ctrl-C: stopping all nodes"); break; }
            _ = terminate.recv() => { say("SIGTERM: stopping all nodes"); break; }
            e = rx.recv() => match e { Some(e) => e, None => break },
            _ = async {
                match look.as_mut() {
                    Some(l) => { l.tick().await; }
                    None => std::future::pending::<()>().await,
                }
            } => {
                if let Some(w) = &watchdog {
                    look_at_nodes(&running, w, &mut frozen, &mut feed_failed);
                }
                continue;
            }
        };
        match event {
            Event::Exited { name, code, signal } => {
                running.remove(&name);
                let Some(spec) = by_name.get(&name) else {
                    continue;
                };
                let ok = code == Some(0);
                if spec.shutdown_on_exit {
                    say(&format!(
                        "{name} finished ({}): stopping the launch",
                        describe(code, signal)
                    ));
                    exit_code = code.unwrap_or(1);
                    break;
                }
                if spec.respawn {
                    let n = restarts.entry(name.clone()).or_insert(0);
                    *n += 1;
                    say(&format!(
                        "{name} died ({}); respawning in {:.1} s (restart {n})",
                        describe(code, signal),
                        spec.respawn_delay_secs
                    ));
                    let tx = tx.clone();
                    let delay = Duration::from_secs_f64(spec.respawn_delay_secs);
                    tokio::spawn(async move {
                        tokio::time::sleep(delay).await;
                        let _ = tx.send(Event::Respawn(name));
                    });
                } else if ok {
                    say(&format!("{name} finished"));
                } else {
                    say(&format!("{name} died ({})", describe(code, signal)));
                    exit_code = 1;
                }
                if running.is_empty() && !spec.respawn && !by_name.values().any(|s| s.respawn) {
                    break;
                }
            }
            Event::Respawn(name) => {
                let Some(spec) = by_name.get(&name) else {
                    continue;
                };
                match start(spec, log_dir, tx.clone()) {
                    Ok(pid) => {
                        say(&format!("restarted {name} (pid {pid})"));
                        running.insert(name, pid);
                    }
                    Err(e) => say(&format!("could not restart {name}: {e}")),
                }
            }
        }
    }
    if !stop_all(&mut running, &mut rx, grace).await {
        exit_code = exit_code.max(1);
    }
    Ok(exit_code)
}

/// SIGINT to every running process, then SIGKILL to those still there after `grace`.
/// SIGCONT follows the SIGINT, as systemd does, so a stopped node (SIGSTOP, a debugger) wakes
/// to stop cleanly. Returns true when all stopped by themselves.
async fn stop_all(
    running: &mut HashMap<String, u32>,
    rx: &mut mpsc::UnboundedReceiver<Event>,
    grace: Duration,
) -> bool {
    for (name, pid) in running.iter() {
        if let Ok(pid) = i32::try_from(*pid) {
            match kill(Pid::from_raw(pid), Signal::SIGINT) {
                Ok(()) => {
                    let _ = kill(Pid::from_raw(pid), Signal::SIGCONT);
                }
                Err(e) => say(&format!("could not signal {name}: {e}")),
            }
        }
    }
    let deadline = tokio::time::Instant::now() + grace;
    while !running.is_empty() {
        match tokio::time::timeout_at(deadline, rx.recv()).await {
            Ok(Some(Event::Exited { name, code, signal })) => {
                if running.remove(&name).is_some() {
                    say(&format!("{name} stopped ({})", describe(code, signal)));
                }
            }
            Ok(Some(Event::Respawn(_))) => {}
            Ok(None) | Err(_) => break,
        }
    }
    let clean = running.is_empty();
    for (name, pid) in running.drain() {
        say(&format!("{name} did not stop within {grace:?}: killing it"));
        if let Ok(pid) = i32::try_from(pid) {
            let _ = kill(Pid::from_raw(pid), Signal::SIGKILL);
        }
    }
    clean
}
