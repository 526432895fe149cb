#!/usr/bin/env bash
# The qt-therapy package, end to end, on this Debian machine (as root; it installs, upgrades,
# removes and purges the package here): its file list and conffiles, lintian (Debian's own
# checker) on it and on its debug symbols, the unit, the tablets' certificate made at install,
# one simulated session run by the installed start script as the qt-therapy user (its pages
# over HTTPS), the child's data listed, exported and erased by qt-therapy-data (refused while
# the session ran), the refusal without a PIN, an upgrade and a removal that keep
# /var/lib/qt-therapy and the certificate, and a purge that deletes them.
#   bash tests/package/check.sh        QT_PACKAGE_PROFILE=dev reuses the debug build
set -euo pipefail
cd "$(dirname "$0")/../.."
repo=$(pwd)
[ "$(id -u)" = 0 ] || { echo "check.sh: run as root (it installs the package)" >&2; exit 2; }
profile=${QT_PACKAGE_PROFILE:-release}
# The debug build's package is only made to be checked: gzip -1, not xz, whose compression of
# its 146 MB took most of the check's time (packaging/deb/build.sh --compression).
compression=xz
[ "$profile" = dev ] && compression=gzip
work=$(mktemp -d)
state=/var/lib/qt-therapy
# A check stopped halfway purges what it installed, so the next run (or CI) starts clean.
installed=0
cleanup() {
  if [ "$installed" = 1 ]; then
    echo "check.sh: stopped before the end: purging the package it installed" >&2
    apt-get purge -y -qq qt-therapy >/dev/null 2>&1 || true
    rm -rf "$state"
  fi
  rm -rf "$work"
}
trap cleanup EXIT
fail() { echo "check.sh: FAILED: $*" >&2; exit 1; }
step() { echo "== $* (at ${SECONDS}s)"; }
export DEBIAN_FRONTEND=noninteractive

need_apt=()
command -v systemd-analyze >/dev/null || need_apt+=(systemd)
command -v lintian >/dev/null || need_apt+=(lintian)
if [ ${#need_apt[@]} -gt 0 ]; then
  apt-get update -qq && apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi
# It purges at the end: never on a robot whose Q-tables it would delete.
if dpkg -s qt-therapy >/dev/null 2>&1 || [ -d "$state" ]; then
  if [ "${QT_PACKAGE_CHECK_PURGE:-}" != 1 ]; then
    echo "check.sh: qt-therapy is installed here or $state exists; the check would purge it." >&2
    echo "  Run it on a scratch machine, or set QT_PACKAGE_CHECK_PURGE=1 to purge first." >&2
    exit 2
  fi
  step "a previous install: purged first (QT_PACKAGE_CHECK_PURGE=1)"
  apt-get purge -y -qq qt-therapy >/dev/null 2>&1 || true
  rm -rf "$state"
fi

step "build (profile $profile)"
bash packaging/deb/build.sh --profile "$profile" --compression "$compression" --revision 1 --out "$work/r1" | tail -n 2 >"$work/built"
ddeb1=$(head -n 1 "$work/built")
deb1=$(tail -n 1 "$work/built")
[ -f "$deb1" ] && [ -f "$ddeb1" ] || fail "no package built: $(cat "$work/built")"

step "file list and conffiles"
dpkg-deb -c "$deb1" | awk '{print $6}' | sed 's#^\./#/#; s#/$##' | grep -v '^/\?$' | sort >"$work/files"
for f in /usr/lib/qt-therapy/start /lib/systemd/system/qt-therapy.service /etc/qt-therapy/environment \
  /usr/share/qt-therapy/launch/tablet_session.launch.yaml \
  /usr/share/qt-therapy/launch/simulated_session.launch.yaml \
  /usr/share/qt-therapy/models/user_model/migrave_study_c2.json \
  /usr/share/qt-therapy/models/engagement_classifier/synthetic_engagement.json \
  /usr/share/doc/qt-therapy/install.md; do
  grep -qx "$f" "$work/files" || fail "$f is not in the package"
done
for p in launch game-manager behaviour-policy policy-lab user-model engagement-classifier \
  tablet-bridge openface-bridge simulated-child therapist bag report tls data; do
  grep -qx "/usr/bin/qt-therapy-$p" "$work/files" || fail "/usr/bin/qt-therapy-$p is not in the package"
  grep -qx "/usr/share/man/man1/qt-therapy-$p.1.gz" "$work/files" || fail "qt-therapy-$p has no manual page"
done
[ "$(dpkg-deb -c "$deb1" | awk '$6 == "./usr/bin/qt-therapy-data" {print $8}')" = ../lib/qt-therapy/bin/child_data ] ||
  fail "/usr/bin/qt-therapy-data is not a link to /usr/lib/qt-therapy/bin/child_data"
for y in params/*.yaml; do
  grep -qx "/etc/qt-therapy/$(basename "$y")" "$work/files" || fail "$y is not packaged"
done
outside=$(grep -vE '^/(usr/bin/qt-therapy-[a-z-]+|usr/lib/qt-therapy|usr/share/qt-therapy|usr/share/doc/qt-therapy|usr/share/man/man1/qt-therapy-[a-z-]+\.1\.gz|usr/share/lintian/overrides/qt-therapy|etc/qt-therapy|lib/systemd/system/qt-therapy.service)(/|$)' "$work/files" |
  grep -vxE '/usr|/usr/bin|/usr/lib|/usr/share|/usr/share/doc|/usr/share/man|/usr/share/man/man1|/usr/share/lintian|/usr/share/lintian/overrides|/etc|/lib|/lib/systemd|/lib/systemd/system' || true)
[ -z "$outside" ] || fail "files outside the package's places: $outside"
dpkg-deb -e "$deb1" "$work/control"
dpkg-deb -c "$deb1" | awk '$1 ~ /^-/ {print $6}' | sed 's#^\./#/#' | grep '^/etc/' | sort >"$work/etc_files"
sort "$work/control/conffiles" | diff "$work/etc_files" - || fail "conffiles are not exactly the files under /etc"
grep -q '^Depends:.*libc6' "$work/control/control" || fail "no libc6 dependency"

step "lintian"
# Every tag lintian shows fails the check: an error, a warning, and an override that no longer
# matches anything (packaging/deb/lintian-overrides gives each override its reason).
for pkg in "$deb1" "$ddeb1"; do
  set +e
  lintian --fail-on error,warning "$pkg" >"$work/lintian.out" 2>&1
  rc=$?
  set -e
  grep -v 'running with root privileges' "$work/lintian.out" >"$work/lintian.tags" || true
  if [ "$rc" != 0 ] || [ -s "$work/lintian.tags" ]; then
    cat "$work/lintian.tags"
    fail "lintian on $(basename "$pkg") (exit $rc): fix each tag above or override it with its reason"
  fi
done
echo "lintian: no tags ($(lintian --version))"

step "install"
installed=1
apt-get install -y -qq "$deb1" >"$work/install.out" 2>&1 || { cat "$work/install.out"; fail "apt install"; }
grep qt-therapy: "$work/install.out" || true
grep -q "set the therapist page's PIN" "$work/install.out" || fail "the install did not say to set the PIN"
getent passwd qt-therapy >/dev/null || fail "no qt-therapy user"
[ "$(stat -c '%U:%G %a' "$state")" = "qt-therapy:qt-therapy 750" ] || fail "$state: $(stat -c '%U:%G %a' "$state")"
[ "$(stat -c '%U:%G %a' /etc/qt-therapy/environment)" = "root:qt-therapy 640" ] ||
  fail "environment: $(stat -c '%U:%G %a' /etc/qt-therapy/environment)"
[ -L /etc/systemd/system/multi-user.target.wants/qt-therapy.service ] || fail "the service is not enabled"
qt-therapy-launch --help >/dev/null || fail "qt-therapy-launch does not run"
# A manual page as man shows it (where dpkg installs man pages and man is there).
if [ -f /usr/share/man/man1/qt-therapy-data-erase.1.gz ] && command -v man >/dev/null; then
  MANWIDTH=200 man -P cat qt-therapy-data-erase 2>/dev/null | grep -q -- '--rewrite-damaged' ||
    fail "man qt-therapy-data-erase does not show its options"
fi
# The debug symbols: one file per program, found by its build id where gdb and Rust's
# backtraces look.
dpkg-deb -c "$ddeb1" | awk '{print $6}' >"$work/dbg_files"
for f in /usr/lib/qt-therapy/bin/*; do
  id=$(readelf -n "$f" | sed -n 's/^\s*Build ID: *//p')
  grep -qx "./usr/lib/debug/.build-id/${id:0:2}/${id:2}.debug" "$work/dbg_files" ||
    fail "qt-therapy-dbgsym has no debug file for $f (build id ${id:-none})"
  ! readelf -SW "$f" | grep -q -e ' \.symtab ' -e ' \.debug_info ' -e ' \.debug_line ' || fail "$f is not stripped"
done

step "the tablets' certificate, made at install"
tls=/etc/qt-therapy/tls
for f in ca.crt ca.key server.crt server.key; do
  [ -s "$tls/$f" ] || fail "no $tls/$f after install"
done
[ "$(stat -c '%U:%G %a' "$tls/ca.key")" = "root:root 600" ] || fail "ca.key: $(stat -c '%U:%G %a' "$tls/ca.key")"
[ "$(stat -c '%U:%G %a' "$tls/server.key")" = "qt-therapy:qt-therapy 600" ] ||
  fail "server.key: $(stat -c '%U:%G %a' "$tls/server.key")"
fingerprint=$(qt-therapy-tls fingerprint)
grep -q "CA SHA-256 fingerprint: $fingerprint" "$work/install.out" || fail "the install did not print the CA's fingerprint"
qt-therapy-tls export-ca "$work/tablet-ca.crt" >/dev/null && cmp -s "$work/tablet-ca.crt" "$tls/ca.crt" ||
  fail "qt-therapy-tls export-ca did not write the CA"
grep -q "tls_key_file: \"$tls/server.key\"" /etc/qt-therapy/tablet_bridge.yaml || fail "tablet_bridge.yaml names no certificate"
# The service user loads the certificate and key the bridge is to serve with, and cannot read the CA's key.
runuser -u qt-therapy -- env QT_PARAMS_DIR=/etc/qt-therapy QT_TABLET_PIN=8642 RUST_BACKTRACE=0 \
  /usr/lib/qt-therapy/bin/tablet_bridge --check >"$work/check.out" 2>&1 || { cat "$work/check.out"; fail "tablet_bridge --check as qt-therapy"; }
! runuser -u qt-therapy -- cat "$tls/ca.key" >/dev/null 2>&1 || fail "the service user can read the CA's key"
(cd "$tls" && sha256sum ca.crt ca.key server.crt server.key) >"$work/tls.before"

step "systemd-analyze verify"
systemd-analyze verify /lib/systemd/system/qt-therapy.service 2>&1 | tee "$work/verify.out"
if grep -v -e 'Failed to connect\|System has not been booted\|not supported' "$work/verify.out" | grep -q .; then
  fail "systemd-analyze verify complained"
fi

# As systemd runs the service: its user, its environment file, its directory and umask.
cat >"$work/run-service.sh" <<SERVICE
cd $state
umask 0027
set -a
. /etc/qt-therapy/environment
set +a
export STATE_DIRECTORY=$state
exec $repo/tests/loopback-netns runuser -u qt-therapy -- /usr/lib/qt-therapy/start
SERVICE
run_service() { timeout 300 bash "$work/run-service.sh"; }

step "no PIN, a short PIN: refused with the reason, exit 78"
set +e
run_service >"$work/refused.out" 2>&1
rc=$?
set -e
[ "$rc" = 78 ] || { cat "$work/refused.out"; fail "exit $rc without a PIN, not 78"; }
grep -q "no QT_TABLET_PIN" "$work/refused.out" || fail "the refusal does not name QT_TABLET_PIN"
sed -i 's/^QT_TABLET_PIN=.*/QT_TABLET_PIN=12/' /etc/qt-therapy/environment
set +e
run_service >"$work/refused.out" 2>&1
rc=$?
set -e
[ "$rc" = 78 ] || { cat "$work/refused.out"; fail "exit $rc with a 2-character PIN, not 78"; }
grep -q "at least 4 characters" "$work/refused.out" || fail "the refusal does not say why: $(cat "$work/refused.out")"

step "one simulated session by the installed start script; erasing its child's data is refused meanwhile"
sed -i 's/^QT_TABLET_PIN=.*/QT_TABLET_PIN=8642/; s/^QT_THERAPY_LAUNCH=.*/QT_THERAPY_LAUNCH=simulated_session/' \
  /etc/qt-therapy/environment
child=sim-child-1 # simulated_session.launch.yaml's user
timeout 300 bash "$work/run-service.sh" >"$work/session.out" 2>&1 &
service=$!
stop_service() { kill "$service" 2>/dev/null || true; wait "$service" 2>/dev/null || true; }
# The session's journal is there from its start until the service stops: the session runs.
for _ in $(seq 1 240); do
  if ls "$state"/sessions/*/*.journal >/dev/null 2>&1; then break; fi
  kill -0 "$service" 2>/dev/null || break
  sleep 0.5
done
journal=$(ls "$state"/sessions/*/*.journal 2>/dev/null | head -n 1)
[ -n "$journal" ] || { stop_service; tail -n 40 "$work/session.out"; fail "no session journal while the service ran"; }
set +e
qt-therapy-data erase --user "$child" --yes >"$work/erase-live.out" 2>&1
rc=$?
set -e
[ "$rc" = 4 ] || { stop_service; cat "$work/erase-live.out"; fail "qt-therapy-data erase during the session exited $rc, not 4 (refused)"; }
grep -q "^refused: session .* of this user is running" "$work/erase-live.out" ||
  { stop_service; cat "$work/erase-live.out"; fail "the refusal does not say the session runs"; }
[ -f "$journal" ] || { stop_service; fail "erase refused but $journal is gone"; }
wait "$service" || { tail -n 40 "$work/session.out"; fail "the simulated session did not end cleanly"; }
run=$(ls -d "$state"/sessions/*/ | head -n 1)
run=${run%/}
[ -s "$run/session.mcap" ] || fail "no bag in $run"
[ "$(stat -c %U "$run/session.mcap")" = qt-therapy ] || fail "the bag is not the service user's"
summary=$(ls "$run"/*.summary.json 2>/dev/null | head -n 1)
[ -n "$summary" ] || fail "no session summary in $run"
grep -q '"sequences_played": 10,' "$summary" || fail "the session did not play 10 sequences: $(cat "$summary")"
grep -q "serving the tablet pages over HTTPS" "$run/logs/tablet_bridge.log" ||
  fail "the installed bridge did not serve over HTTPS: $(tail -n 5 "$run/logs/tablet_bridge.log")"
ls "$run"/q_tables/cluster_*.json >/dev/null || fail "no Q-table learned in $run/q_tables"
(cd /tmp && qt-therapy-report) >"$work/report.out" || fail "qt-therapy-report"
grep -q "$run" "$work/report.out" && [ -s "$run/report.html" ] || fail "the report of the last run: $(cat "$work/report.out")"
# The child's progress across the stored runs, kept beside the run so erase must find it.
grep -q '^    sessions_root: "/var/lib/qt-therapy/sessions"$' /etc/qt-therapy/tablet_bridge.yaml ||
  fail "the installed tablet_bridge.yaml does not read the children from the service's runs"
progress=$run/progress-$child.html
(cd /tmp && qt-therapy-report --user "$child" --output "$progress") >"$work/progress.out" ||
  fail "qt-therapy-report --user $child"
grep -q "^$child: 1 session under " "$work/progress.out" && grep -q "Progress of $child" "$progress" ||
  fail "the progress report of $child: $(cat "$work/progress.out")"

step "a child's data: qt-therapy-data list, export, erase (the service stopped)"
session=$(basename "$summary" .summary.json)
user_files=("$run/$session.jsonl" "$run/$session.journal" "$summary" "$run/session.mcap" "$run/report.html" "$progress")
qt-therapy-data list --user "$child" >"$work/list.out" 2>&1 || { cat "$work/list.out"; fail "qt-therapy-data list"; }
for f in "${user_files[@]}"; do
  [ -f "$f" ] || fail "no $f after the session"
  grep -q "^  $f \[" "$work/list.out" || { cat "$work/list.out"; fail "qt-therapy-data list does not name $f"; }
done
mkdir "$work/export"
archive=$work/export/$child.tar.gz
qt-therapy-data export --user "$child" --output "$archive" >"$work/export.out" 2>&1 ||
  { cat "$work/export.out"; fail "qt-therapy-data export"; }
[ "$(stat -c %a "$archive")" = 600 ] || fail "the export archive is mode $(stat -c %a "$archive"), not 600"
[ "$(tar -tzf "$archive" | head -n 1)" = "child-data-$child/MANIFEST.txt" ] || fail "the archive does not start with its MANIFEST.txt"
tar -C "$work/export" -xzf "$archive"
manifest=$work/export/child-data-$child/MANIFEST.txt
grep -q "holds of user \"$child\"" "$manifest" || fail "the manifest does not name the user: $(head -n 3 "$manifest")"
for f in "${user_files[@]}"; do
  grep -q "^    from $f\$" "$manifest" || fail "the manifest does not list $f"
done
copy=$(find "$work/export" -name "$(basename "$summary")" | head -n 1)
[ -n "$copy" ] && cmp -s "$copy" "$summary" || fail "the archive's session summary is not the session's, byte for byte"
exported_bag=$(find "$work/export" -name '*.mcap' | head -n 1)
qt-therapy-bag info "$exported_bag" >"$work/bag-info.out" 2>&1 || { cat "$work/bag-info.out"; fail "the exported bag does not read"; }
set +e
qt-therapy-data erase --user "$child" --yes >"$work/erase.out" 2>&1
rc=$?
set -e
[ "$rc" = 0 ] || { cat "$work/erase.out"; fail "qt-therapy-data erase exited $rc with the service stopped"; }
for f in "${user_files[@]}"; do
  [ ! -e "$f" ] || fail "erase left $f"
done
left=$(grep -rlw -- "$child" "$state"; find "$state" -name "*$child*")
[ -z "$left" ] || fail "files under $state still name $child after erase: $left"
qt-therapy-data list --user "$child" >"$work/list.out" 2>&1 && grep -q "nothing of this user found" "$work/list.out" ||
  { cat "$work/list.out"; fail "qt-therapy-data list still finds $child after erase"; }

step "upgrade to revision 2 keeps the state and a changed conffile"
# A Q-table as the robot would hold it, and a local change to a parameter file.
cp "$run"/q_tables/cluster_0.json "$state/q_tables/cluster_0.json"
chown qt-therapy:qt-therapy "$state/q_tables/cluster_0.json"
echo "# changed on this robot" >>/etc/qt-therapy/game_manager.yaml
sum_state() { (cd "$state" && find . -type f -print0 | sort -z | xargs -0 md5sum); }
sum_state >"$work/state.before"
deb2=$(bash packaging/deb/build.sh --profile "$profile" --compression "$compression" --revision 2 --out "$work/r2" | tail -n 1)
apt-get install -y -qq "$deb2" >"$work/upgrade.out" 2>&1 || { cat "$work/upgrade.out"; fail "apt upgrade"; }
dpkg-query -W -f '${Version}\n' qt-therapy | grep -q -- '-2$' || fail "revision 2 is not installed"
sum_state | diff "$work/state.before" - || fail "the upgrade changed $state"
grep -q "changed on this robot" /etc/qt-therapy/game_manager.yaml || fail "the upgrade dropped a local change"
grep -q '^QT_TABLET_PIN=8642' /etc/qt-therapy/environment || fail "the upgrade dropped the PIN"
grep -q "kept the CA" "$work/upgrade.out" || fail "the upgrade did not say it kept the CA"
(cd "$tls" && sha256sum ca.crt ca.key server.crt server.key) | diff "$work/tls.before" - ||
  fail "the upgrade changed the tablets' certificate"

step "remove keeps the state"
apt-get remove -y -qq qt-therapy >"$work/remove.out" 2>&1 || { cat "$work/remove.out"; fail "apt remove"; }
grep -q "kept in $state" "$work/remove.out" || fail "the removal did not say the state is kept"
[ ! -e /usr/bin/qt-therapy-launch ] || fail "programs left after remove"
sum_state | diff "$work/state.before" - || fail "the removal changed $state"
getent passwd qt-therapy >/dev/null || fail "the removal deleted the user"
(cd "$tls" && sha256sum ca.crt ca.key server.crt server.key) | diff "$work/tls.before" - ||
  fail "the removal changed the tablets' certificate"

step "purge deletes it, saying so"
apt-get purge -y -qq qt-therapy >"$work/purge.out" 2>&1 || { cat "$work/purge.out"; fail "apt purge"; }
grep -q "deleting $state" "$work/purge.out" || fail "the purge did not say what it deletes"
grep -q "deleting the tablets' certificates" "$work/purge.out" || fail "the purge did not say it deletes the certificates"
[ ! -e "$state" ] || fail "$state left after purge"
[ ! -e /etc/qt-therapy ] || fail "/etc/qt-therapy left after purge"
! getent passwd qt-therapy >/dev/null || fail "the user left after purge"
installed=0

echo "package check: all passed"
