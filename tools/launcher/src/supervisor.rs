//! Runs the processes of a launch description: starts each with its output prefixed by its
//! name, reports a process that dies, respawns those marked `respawn`, and stops everything
//! (SIGINT, then SIGKILL after a grace period) on Ctrl-C, SIGTERM or an `on_exit: shutdown`.

use crate::description::ProcessSpec;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::collections::HashMap;
use std::process::Stdio;
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

fn start(spec: &ProcessSpec, events: mpsc::UnboundedSender<Event>) -> std::io::Result<u32> {
    let mut cmd = Command::new(&spec.program);
    cmd.args(&spec.args)
        .envs(spec.env.iter().cloned())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
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
        forwarders.push(forward_lines(out, name.clone(), |name, line| {
            println!("[{name}] {line}")
        }));
    }
    if let Some(err) = child.stderr.take() {
        forwarders.push(forward_lines(err, name.clone(), |name, line| {
            eprintln!("[{name}] {line}")
        }));
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

/// Prints each line of a node's output pipe, prefixed by its name, until the pipe closes.
fn forward_lines<R>(pipe: R, name: String, print: fn(&str, &str)) -> tokio::task::JoinHandle<()>
where
    R: tokio::io::AsyncRead + Unpin + Send + 'static,
{
    tokio::spawn(async move {
        let mut lines = BufReader::new(pipe).lines();
        while let Ok(Some(line)) = lines.next_line().await {
            print(&name, &line);
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

/// Runs `specs` to the end; returns the launcher's exit code.
pub async fn run(specs: Vec<ProcessSpec>, grace: Duration) -> anyhow::Result<i32> {
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
        match start(spec, tx.clone()) {
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
    loop {
        if running.is_empty() && !by_name.values().any(|s| s.respawn) {
            break;
        }
        let event = tokio::select! {
            _ = interrupt.recv() => { say("Ctrl-C: stopping all nodes"); break; }
            _ = terminate.recv() => { say("SIGTERM: stopping all nodes"); break; }
            e = rx.recv() => match e { Some(e) => e, None => break },
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
                match start(spec, tx.clone()) {
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
/// Returns true when all stopped by themselves.
async fn stop_all(
    running: &mut HashMap<String, u32>,
    rx: &mut mpsc::UnboundedReceiver<Event>,
    grace: Duration,
) -> bool {
    for (name, pid) in running.iter() {
        if let Ok(pid) = i32::try_from(*pid)
            && let Err(e) = kill(Pid::from_raw(pid), Signal::SIGINT)
        {
            say(&format!("could not signal {name}: {e}"));
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
