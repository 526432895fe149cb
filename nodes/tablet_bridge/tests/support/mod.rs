//! Helpers of the browser test: child processes killed on drop, deadlines on every wait, the
//! robot's CA trusted the way a tablet trusts it (an NSS database, Chromium's trust store on
//! Linux), a WebDriver page, and axe-core (Deque's accessibility engine) run inside it against
//! WCAG 2.1 AA and axe's best practices. (The loopback namespace every DDS process runs in is
//! `loopback_netns`.)

use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

pub use loopback_netns::workspace_root;

/// `name` on PATH, if it is there.
pub fn which(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// A child process that is killed when the test ends, however it ends.
pub struct Guard {
    pub child: Child,
    pub name: &'static str,
}

impl Guard {
    pub fn spawn(name: &'static str, command: &mut Command) -> Guard {
        let child = command
            .spawn()
            .unwrap_or_else(|e| panic!("starting {name}: {e}"));
        Guard { child, name }
    }

    /// SIGINT, then the exit code within `deadline` (None if it had to be killed).
    pub fn interrupt(mut self, deadline: Duration) -> Option<i32> {
        let pid = self.child.id().to_string();
        let _ = Command::new("kill").args(["-INT", &pid]).status();
        let start = Instant::now();
        while start.elapsed() < deadline {
            if let Ok(Some(status)) = self.child.try_wait() {
                return status.code();
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        eprintln!("{} did not exit within {deadline:?} of SIGINT", self.name);
        None
    }
}

impl Drop for Guard {
    /// SIGINT first, so a launcher stops the nodes it started (a SIGKILLed launcher leaves
    /// them running); SIGKILL after 10 s.
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let pid = self.child.id().to_string();
            let _ = Command::new("kill").args(["-INT", &pid]).status();
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(10) {
                if let Ok(Some(_)) = self.child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Polls `probe` every 100 ms until it gives a value, or panics naming `what` at `deadline`.
pub async fn until<T, F, Fut>(what: &str, deadline: Duration, mut probe: F) -> T
where
    F: FnMut() -> Fut,
    Fut: Future<Output = Option<T>>,
{
    let start = Instant::now();
    loop {
        if let Some(v) = probe().await {
            return v;
        }
        assert!(
            start.elapsed() < deadline,
            "timed out after {deadline:?} waiting for {what}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Whether something answers on 127.0.0.1:`port`.
pub fn port_open(port: u16) -> bool {
    std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
}

/// The host name the pages are opened at: Chromium maps it to 127.0.0.1 (it is in the
/// server certificate, as the robot's own name is).
pub const ROBOT_HOST: &str = "qtrobot.test";

/// The raw HTTP/1.1 response head to `request`, over TLS to `ROBOT_HOST` trusting only the CA
/// of `ca_dir` (tests the server without a browser).
pub async fn raw_https(port: u16, ca_dir: &Path, request: &str) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut roots = rustls::RootCertStore::empty();
    roots
        .add(tablet_bridge::certificates::read_ca(ca_dir).expect("the CA"))
        .expect("a root");
    let config = rustls::ClientConfig::builder_with_provider(tablet_bridge::tls::provider())
        .with_safe_default_protocol_versions()
        .expect("versions")
        .with_root_certificates(roots)
        .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(std::sync::Arc::new(config));
    let tcp = tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .expect("connect");
    let name = rustls::pki_types::ServerName::try_from(ROBOT_HOST).expect("name");
    let mut s = connector.connect(name, tcp).await.expect("TLS handshake");
    s.write_all(request.as_bytes()).await.expect("write");
    let mut buf = vec![0u8; 4096];
    let read = tokio::time::timeout(Duration::from_secs(5), s.read(&mut buf)).await;
    let n = read.ok().and_then(Result::ok).unwrap_or(0);
    String::from_utf8_lossy(&buf[..n]).into_owned()
}

/// A home directory whose NSS database (`.pki/nssdb`, where Chromium on Linux keeps the
/// certificates its user installed) trusts the CA in `ca_file` for TLS servers, as a tablet
/// does once the robot's CA is installed on it. Made with NSS's own `certutil`.
pub fn home_trusting(home: &Path, ca_file: &Path) {
    let db = home.join(".pki/nssdb");
    std::fs::create_dir_all(&db).expect("nssdb dir");
    let db = format!("sql:{}", db.display());
    let run = |args: &[&str]| {
        let out = Command::new("certutil")
            .args(args)
            .stdin(std::process::Stdio::null())
            .output()
            .expect("certutil runs");
        assert!(
            out.status.success(),
            "certutil {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    run(&["-N", "-d", &db, "--empty-password"]);
    let ca = ca_file.display().to_string();
    run(&[
        "-A",
        "-d",
        &db,
        "-n",
        "QTrobot therapy CA",
        "-t",
        "C,,",
        "-i",
        &ca,
    ]);
}

/// One browser window (one WebDriver session, its own fresh profile) showing one page.
pub struct Page {
    pub client: Client,
    pub name: &'static str,
}

impl Page {
    pub async fn open(
        name: &'static str,
        driver_port: u16,
        profile: &Path,
        size: (u32, u32),
    ) -> Page {
        let args = [
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-dev-shm-usage",
            "--hide-scrollbars",
        ];
        let mut args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        args.push(format!("--user-data-dir={}", profile.display()));
        args.push(format!("--host-resolver-rules=MAP {ROBOT_HOST} 127.0.0.1"));
        args.push(format!("--window-size={},{}", size.0, size.1));
        let mut caps = serde_json::Map::new();
        caps.insert("browserName".into(), json!("chrome"));
        caps.insert("goog:chromeOptions".into(), json!({"args": args}));
        let connector = hyper_util::client::legacy::connect::HttpConnector::new();
        let client = ClientBuilder::new(connector)
            .capabilities(caps)
            .connect(&format!("http://127.0.0.1:{driver_port}"))
            .await
            .unwrap_or_else(|e| panic!("{name}: starting a Chromium session: {e}"));
        let page = Page { client, name };
        page.resize(size.0, size.1).await;
        page
    }

    pub async fn js(&self, script: &str, args: Vec<Value>) -> Value {
        self.client
            .execute(script, args)
            .await
            .unwrap_or_else(|e| panic!("{}: script failed: {e}", self.name))
    }

    /// The text of the first element matching `css` ("" when there is none).
    pub async fn text(&self, css: &str) -> String {
        let v = self
            .js(
                "const e = document.querySelector(arguments[0]); return e ? e.textContent : '';",
                vec![json!(css)],
            )
            .await;
        v.as_str().unwrap_or_default().to_string()
    }

    pub async fn count(&self, css: &str) -> u64 {
        let v = self
            .js(
                "return document.querySelectorAll(arguments[0]).length;",
                vec![json!(css)],
            )
            .await;
        v.as_u64().unwrap_or(0)
    }

    pub async fn click(&self, css: &str) {
        let e = self.client.find(Locator::Css(css)).await;
        let e = e.unwrap_or_else(|err| panic!("{}: no {css}: {err}", self.name));
        e.click()
            .await
            .unwrap_or_else(|err| panic!("{}: clicking {css}: {err}", self.name));
    }

    pub async fn type_into(&self, css: &str, text: &str) {
        let e = self.client.find(Locator::Css(css)).await;
        let e = e.unwrap_or_else(|err| panic!("{}: no {css}: {err}", self.name));
        e.clear()
            .await
            .unwrap_or_else(|err| panic!("{}: clearing {css}: {err}", self.name));
        e.send_keys(text)
            .await
            .unwrap_or_else(|err| panic!("{}: typing into {css}: {err}", self.name));
    }

    /// Waits until the text of `css` contains `wanted`.
    pub async fn wait_text(&self, css: &str, wanted: &str, deadline: Duration) -> String {
        let what = format!("{}: {css} to contain {wanted:?}", self.name);
        until(&what, deadline, || async {
            let t = self.text(css).await;
            t.contains(wanted).then_some(t)
        })
        .await
    }

    pub async fn wait_count(&self, css: &str, n: u64, deadline: Duration) {
        let what = format!("{}: {n} × {css}", self.name);
        until(&what, deadline, || async {
            (self.count(css).await == n).then_some(())
        })
        .await
    }

    /// Sets the viewport (not the window) to `w` x `h`: a tablet's screen has no browser frame.
    pub async fn resize(&self, w: u32, h: u32) {
        let set = |w, h| async move {
            self.client
                .set_window_size(w, h)
                .await
                .unwrap_or_else(|e| panic!("{}: resizing: {e}", self.name))
        };
        // The window's frame is what the window has beyond the viewport; a loaded machine
        // (or a page just printed) may report a size before the window settled, so read
        // until two readings agree, then set again.
        let read = || self.js("return [window.innerWidth, window.innerHeight];", vec![]);
        let (mut ww, mut wh) = (w, h);
        let mut inner = json!(null);
        for _ in 0..5 {
            set(ww, wh).await;
            inner = read().await;
            for _ in 0..20 {
                if inner == json!([w, h]) {
                    return;
                }
                tokio::time::sleep(Duration::from_millis(100)).await;
                let again = read().await;
                if again == inner {
                    break;
                }
                inner = again;
            }
            let got = |i: usize| inner[i].as_u64().unwrap_or(0) as u32;
            ww = (ww + w).saturating_sub(got(0));
            wh = (wh + h).saturating_sub(got(1));
        }
        panic!("{}: viewport {inner} after resizing to {w}x{h}", self.name);
    }

    /// Saves a PNG screenshot of the viewport as `dir/stem.png`.
    pub async fn screenshot(&self, dir: &Path, stem: &str) -> PathBuf {
        let png = self.client.screenshot().await;
        let png = png.unwrap_or_else(|e| panic!("{}: screenshot: {e}", self.name));
        let path = dir.join(format!("{stem}.png"));
        let tmp = dir.join(format!(".{stem}.png.tmp"));
        std::fs::write(&tmp, png).expect("writing a screenshot");
        std::fs::rename(&tmp, &path).expect("renaming a screenshot");
        path
    }

    /// Opens a second WebSocket from this page to `path`, sends `messages` (strings are sent
    /// as they are, anything else as JSON), waits `wait_ms` and returns what came back,
    /// ending with `{"type":"closed",...}` when the bridge closed it.
    pub async fn raw_socket(&self, path: &str, messages: Vec<Value>, wait_ms: u64) -> Vec<Value> {
        let script = r#"
            const [path, messages, waitMs, done] = arguments;
            const got = [];
            let finished = false;
            const finish = () => { if (!finished) { finished = true; done(got); } };
            const scheme = location.protocol === "https:" ? "wss://" : "ws://";
            const ws = new WebSocket(scheme + location.host + path);
            ws.onmessage = (e) => { try { got.push(JSON.parse(e.data)); } catch (x) { got.push(e.data); } };
            ws.onclose = (e) => { got.push({type: "closed", code: e.code, reason: e.reason}); finish(); };
            ws.onopen = () => {
              for (const m of messages) {
                if (ws.readyState !== WebSocket.OPEN) break;
                ws.send(typeof m === "string" ? m : JSON.stringify(m));
              }
              setTimeout(() => { ws.close(); setTimeout(finish, 500); }, waitMs);
            };
        "#;
        let args = vec![json!(path), json!(messages), json!(wait_ms)];
        let v = self.client.execute_async(script, args).await;
        let v = v.unwrap_or_else(|e| panic!("{}: raw socket: {e}", self.name));
        v.as_array().cloned().unwrap_or_default()
    }
}

/// The processes' output files.
pub struct Logs {
    pub dir: tempfile::TempDir,
}

impl Logs {
    pub fn file(&self, name: &str) -> std::fs::File {
        std::fs::File::create(self.dir.path().join(name)).expect("log file")
    }
    pub fn read(&self, name: &str) -> String {
        std::fs::read_to_string(self.dir.path().join(name)).unwrap_or_default()
    }
    pub fn dump(&self) -> String {
        let mut s = String::new();
        for f in ["launch.out", "launch.err", "chromedriver.log"] {
            let text = self.read(f);
            let tail: Vec<&str> = text.lines().rev().take(80).collect();
            s += &format!("--- {f} (last lines)\n");
            for l in tail.into_iter().rev() {
                s += l;
                s.push('\n');
            }
        }
        s
    }
}

/// The rules axe runs: WCAG 2.0 and 2.1, levels A and AA (what EN 301 549 asks of software),
/// and axe's best practices (one main landmark, a level-one heading, content in landmarks).
const AXE_TAGS: [&str; 5] = ["wcag2a", "wcag2aa", "wcag21a", "wcag21aa", "best-practice"];

/// Where axe-core's script is, as `tests/run.sh` installs it from the npm registry (the
/// version pinned in `nodes/tablet_bridge/tests/axe/package-lock.json`): `$QT_AXE_JS`, or
/// `axe-core/` in `target_dir`; None (after saying why) where it is not installed and the
/// tests may skip. The test passes it to its run inside the namespace as `QT_AXE_JS`.
pub fn axe_script(target_dir: &Path) -> Option<PathBuf> {
    let path = std::env::var_os("QT_AXE_JS").map_or_else(
        || target_dir.join("axe-core/node_modules/axe-core/axe.min.js"),
        PathBuf::from,
    );
    if path.is_file() {
        return Some(path);
    }
    loopback_netns::skip_or_fail(&format!(
        "axe-core is not installed ({} is missing); tests/run.sh installs it with npm ci from \
         nodes/tablet_bridge/tests/axe/",
        path.display()
    ));
    None
}

/// axe-core's runs in this process and the time they took (µs), printed by the tests.
static AXE_RUNS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
static AXE_MICROS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// `axe-core: N runs, S s` so far in this process.
pub fn axe_spent() -> String {
    use std::sync::atomic::Ordering::Relaxed;
    format!(
        "axe-core: {} runs, {:.1} s",
        AXE_RUNS.load(Relaxed),
        AXE_MICROS.load(Relaxed) as f64 / 1e6
    )
}

/// axe-core's script, read once from `$QT_AXE_JS`.
fn axe_source() -> &'static str {
    static SOURCE: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    SOURCE.get_or_init(|| {
        let path = std::env::var_os("QT_AXE_JS").expect("QT_AXE_JS names axe.min.js");
        std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", Path::new(&path).display()))
    })
}

impl Page {
    /// Runs axe-core on the page as it is now and panics naming every violation (rule,
    /// impact, the elements and why) of WCAG 2.1 A/AA and axe's best practices; `state` says
    /// which page and state it was (e.g. `therapist, 50 sessions, de, 800x1280`). The script is
    /// injected once per document.
    pub async fn assert_accessible(&self, state: &str) {
        let started = Instant::now();
        let present = self
            .js("return typeof window.axe === 'object';", vec![])
            .await;
        if present != json!(true) {
            self.js(&format!("{};\nreturn true;", axe_source()), vec![])
                .await;
        }
        let script = r#"
            const [tags, done] = arguments;
            axe.run(document, { runOnly: { type: "tag", values: tags } })
              .then((r) => done(r.violations.map((v) => ({
                id: v.id, impact: v.impact, help: v.help,
                nodes: v.nodes.slice(0, 5).map((n) => n.target.join(" ") + ": " +
                  (n.failureSummary || "").replace(/\s+/g, " ")),
                count: v.nodes.length }))))
              .catch((e) => done([{ id: "axe-error", impact: "", help: String(e), nodes: [], count: 1 }]));
        "#;
        let v = self
            .client
            .execute_async(script, vec![json!(AXE_TAGS)])
            .await
            .unwrap_or_else(|e| panic!("{}: axe-core did not run ({state}): {e}", self.name));
        let violations = v.as_array().cloned().unwrap_or_default();
        let spent = u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX);
        AXE_RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        AXE_MICROS.fetch_add(spent, std::sync::atomic::Ordering::Relaxed);
        assert!(
            violations.is_empty(),
            "{}: {} accessibility rule(s) violated ({state}):\n{}",
            self.name,
            violations.len(),
            serde_json::to_string_pretty(&violations).unwrap_or_default()
        );
    }

    /// The page printed to PDF (A4 portrait, as a tablet's print dialog gives it), saved as
    /// `dir/stem.pdf`; returns the PDF's bytes.
    pub async fn print_pdf(&self, dir: &Path, stem: &str) -> Vec<u8> {
        let config = fantoccini::wd::PrintConfiguration::builder()
            .build()
            .unwrap_or_else(|e| panic!("{}: print configuration: {e}", self.name));
        let pdf = self.client.print(config).await;
        let pdf = pdf.unwrap_or_else(|e| panic!("{}: printing: {e}", self.name));
        std::fs::write(dir.join(format!("{stem}.pdf")), &pdf).expect("writing a PDF");
        pdf
    }
}
