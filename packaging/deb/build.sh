#!/usr/bin/env bash
# Builds the qt-therapy Debian package from this workspace with dpkg-deb (Debian's own tool,
# kept with dpkg itself): the suite's fourteen programs (stripped) and their manual pages
# (each program writes its own from its command line's definition), its parameters as
# conffiles in /etc/qt-therapy, models and launch files in /usr/share/qt-therapy, the systemd
# unit; and beside it qt-therapy-dbgsym, the programs' debug symbols, as Debian's own builds
# make them. Lintian accepts both (tests/package/check.sh runs it).
#   bash packaging/deb/build.sh [--revision N] [--profile release|dev] [--out DIR] [--compression xz|gzip]
# Prints the path of the .ddeb, then of the .deb. The layout and why: docs/install.md.
set -euo pipefail
cd "$(dirname "$0")/../.."
umask 022
# The package's maintainer, in the control file, the changelog and the copyright file.
maintainer="QTrobot therapy suite maintainers <maintainers@users.noreply.h-seed-69233df3.example>"

revision=1
profile=release
# The .deb's data: xz as Debian ships (the default), or gzip -1 for a package only made to be
# checked here: xz took 100 s of CPU per package of the debug build's 146 MB (dpkg-deb 1.21),
# gzip -1 a few; both are packages dpkg and lintian take alike.
compression=xz
out=${CARGO_TARGET_DIR:-target}/deb
while [ $# -gt 0 ]; do
  case "$1" in
    --revision) revision=$2; shift 2 ;;
    --profile) profile=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --compression) compression=$2; shift 2 ;;
    *) echo "build.sh: unknown argument $1 (--revision N, --profile P, --out DIR, --compression C)" >&2; exit 2 ;;
  esac
done
out=$(realpath -m "$out")
case "$revision" in '' | *[!0-9]*) echo "build.sh: --revision $revision is not a number" >&2; exit 2 ;; esac
case "$compression" in
  xz) deb_compression=(-Zxz) ;;
  gzip) deb_compression=(-Zgzip -z1) ;;
  *) echo "build.sh: --compression $compression is not xz or gzip" >&2; exit 2 ;;
esac

need_apt=()
command -v dpkg-deb >/dev/null || need_apt+=(dpkg)
command -v dpkg-shlibdeps >/dev/null || need_apt+=(dpkg-dev)
command -v objcopy >/dev/null || need_apt+=(binutils)
command -v python3 >/dev/null || need_apt+=(python3)
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi
  $SUDO apt-get update -qq && $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

# package -> the binary its crate builds -> its name in /usr/bin (qt-therapy-*, so nothing
# another package installs can collide).
programs=(
  "engagement_classifier engagement_classifier engagement-classifier"
  "user_model user_model user-model"
  "behaviour_policy behaviour_policy behaviour-policy"
  "policy_lab policy_lab policy-lab"
  "game_manager game_manager game-manager"
  "tablet_bridge tablet_bridge tablet-bridge"
  "tablet_bridge tablet_tls tls"
  "openface_bridge openface_bridge openface-bridge"
  "simulated_child simulated_child simulated-child"
  "therapist_console therapist therapist"
  "bag bag bag"
  "launcher launch launch"
  "session_report session_report report"
  "child_data child_data data"
)
packages=()
for p in "${programs[@]}"; do
  read -r crate _ _ <<<"$p"
  [[ " ${packages[*]} " == *" $crate "* ]] || packages+=(-p "$crate")
done
# The dev profile packages the binaries the tests ran (.ci/run): built as the workspace's
# build resolves their features (tests/Cargo.toml pins them), so cargo has them already; a
# build of these packages alone would resolve some features otherwise and build them again.
if [ "$profile" = dev ]; then
  cargo build --profile dev --workspace --bins
else
  cargo build --profile "$profile" --bins "${packages[@]}"
fi
target=${CARGO_TARGET_DIR:-target}
case "$profile" in dev) bin_dir=$target/debug ;; *) bin_dir=$target/$profile ;; esac

version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
arch=$(dpkg --print-architecture)
name=qt-therapy_${version}-${revision}_${arch}
root=$out/$name
dbg=$out/qt-therapy-dbgsym_${version}-${revision}_${arch}
rm -rf "$root" "$dbg"
mkdir -p "$root/DEBIAN" "$root/usr/bin" "$root/usr/lib/qt-therapy/bin" "$root/etc/qt-therapy" \
  "$root/usr/share/qt-therapy/launch" "$root/usr/share/qt-therapy/models" \
  "$root/usr/share/doc/qt-therapy" "$root/usr/share/man/man1" "$root/lib/systemd/system" \
  "$dbg/DEBIAN" "$dbg/usr/share/doc"
# The changelog's and the manual pages' date: the commit's, so a rebuild makes the same files.
if [ -z "${SOURCE_DATE_EPOCH:-}" ]; then
  SOURCE_DATE_EPOCH=$(git log -1 --format=%ct 2>/dev/null || date +%s)
fi
commit=$(git describe --always --dirty --abbrev=12 2>/dev/null || true)

# The programs, stripped as Debian's dh_strip does: their debug information (line tables, for
# backtraces) goes to qt-therapy-dbgsym under /usr/lib/debug/.build-id/, where gdb and Rust's
# own backtraces find it by the binary's build id once that package is installed.
build_ids=()
for p in "${programs[@]}"; do
  read -r _ bin public <<<"$p"
  f=$root/usr/lib/qt-therapy/bin/$bin
  install -m 0755 "$bin_dir/$bin" "$f"
  id=$(readelf -n "$f" | sed -n 's/^\s*Build ID: *//p')
  [ -n "$id" ] || { echo "build.sh: $bin has no build id (the linker's --build-id)" >&2; exit 1; }
  debug=$dbg/usr/lib/debug/.build-id/${id:0:2}/${id:2}.debug
  mkdir -p "$(dirname "$debug")"
  objcopy --only-keep-debug --compress-debug-sections "$f" "$debug"
  chmod 0644 "$debug"
  strip --remove-section=.comment --remove-section=.note "$f"
  objcopy --add-gnu-debuglink="$debug" "$f"
  build_ids+=("$id")
  ln -s "../lib/qt-therapy/bin/$bin" "$root/usr/bin/qt-therapy-$public"
  # Its manual pages, from its own clap definition (libs/man_pages), under the installed name.
  "$f" --write-manpages "$root/usr/share/man/man1" "qt-therapy-$public" \
    "$(date -u -d "@$SOURCE_DATE_EPOCH" +%F)" >/dev/null ||
    { echo "build.sh: $bin did not write its manual pages (--write-manpages)" >&2; exit 1; }
done
gzip -9n "$root"/usr/share/man/man1/*.1
install -m 0755 packaging/deb/start "$root/usr/lib/qt-therapy/start"

# Models, launch files, the unit.
install -m 0644 -D -t "$root/usr/share/qt-therapy/models/user_model" nodes/user_model/models/*.json
install -m 0644 -D -t "$root/usr/share/qt-therapy/models/engagement_classifier" \
  nodes/engagement_classifier/models/*.json
install -m 0644 -D -t "$root/usr/share/qt-therapy/models/behaviour_policy" \
  nodes/behaviour_policy/models/*.json
install -m 0644 launch_scripts/tablet_session.launch.yaml launch_scripts/simulated_session.launch.yaml \
  "$root/usr/share/qt-therapy/launch/"
install -m 0644 packaging/deb/qt-therapy.service "$root/lib/systemd/system/"

# Parameters: the workspace's files with the installed paths. Every path a file names must be
# one of these; a path left relative fails the build.
for f in params/*.yaml; do
  sed -e 's#"nodes/user_model/models/#"/usr/share/qt-therapy/models/user_model/#' \
    -e 's#"nodes/engagement_classifier/models/#"/usr/share/qt-therapy/models/engagement_classifier/#' \
    -e 's#"nodes/behaviour_policy/models/#"/usr/share/qt-therapy/models/behaviour_policy/#' \
    -e 's#q_table_dir: "out/q_tables"#q_table_dir: "/var/lib/qt-therapy/q_tables"#' \
    -e 's#sessions_dir: "sessions"#sessions_dir: "/var/lib/qt-therapy/sessions"#' \
    -e 's#sessions_root: "out"#sessions_root: "/var/lib/qt-therapy/sessions"#' \
    -e 's#retention_dir: ""#retention_dir: "/var/lib/qt-therapy/sessions"#' \
    "$f" >"$root/etc/qt-therapy/$(basename "$f")"
done
# The tablets reach the bridge over the robot's network, over HTTPS with the certificate the
# postinst makes in /etc/qt-therapy/tls; the PIN comes from /etc/qt-therapy/environment and
# has no default.
sed -i -e 's#http_bind: "127.0.0.1:8080"#http_bind: "0.0.0.0:8080"#' \
  -e 's#tls_cert_file: ""#tls_cert_file: "/etc/qt-therapy/tls/server.crt"#' \
  -e 's#tls_key_file: ""#tls_key_file: "/etc/qt-therapy/tls/server.key"#' \
  -e 's#^\(\s*\)pin: "1234"#\1pin: ""  \# set QT_TABLET_PIN in /etc/qt-therapy/environment#' \
  "$root/etc/qt-therapy/tablet_bridge.yaml"
grep -q 'tls_key_file: "/etc/qt-therapy/tls/server.key"' "$root/etc/qt-therapy/tablet_bridge.yaml" ||
  { echo "build.sh: the installed tablet_bridge.yaml names no certificate" >&2; exit 1; }
install -m 0640 packaging/deb/environment "$root/etc/qt-therapy/environment"
if grep -nE '"(nodes|out|params|sessions)/|"1234"|: "out"' "$root"/etc/qt-therapy/*.yaml; then
  echo "build.sh: a parameter above still names a workspace path or the example PIN" >&2
  exit 1
fi
# (The certificate is made at install, not packaged.)
for model in $(sed -n 's/.*_file: "\(\/[^"]*\)".*/\1/p' "$root"/etc/qt-therapy/*.yaml | grep -v '^/etc/qt-therapy/tls/' | sort -u); do
  [ -f "$root$model" ] || { echo "build.sh: a parameter names $model, which is not packaged" >&2; exit 1; }
done

doc=$root/usr/share/doc/qt-therapy
install -m 0644 docs/install.md "$doc/install.md"
# The copyright file: ours, the study's model, and every crate the programs link with its
# license (copyright.py, from cargo metadata: the platform's normal dependencies only).
crates=$(printf '%s\n' "${programs[@]}" | awk '{print $1}' | sort -u | paste -sd, -)
cargo metadata --format-version 1 --offline --locked \
  --filter-platform "$(rustc -vV | sed -n 's/^host: //p')" >"$out/metadata.json"
python3 packaging/deb/copyright.py --metadata "$out/metadata.json" --crates "$crates" \
  --maintainer "$maintainer" --rustc "$(rustc --version)" >"$doc/copyright"
rm -f "$out/metadata.json"
# Debian's changelog of this build (a package has one; its version is the package's).
{
  echo "qt-therapy (${version}-${revision}) unstable; urgency=medium"
  echo
  echo "  * qt-therapy ${version}, package revision ${revision}${commit:+, built from commit $commit}."
  echo
  echo " -- ${maintainer}  $(date -u -R -d "@$SOURCE_DATE_EPOCH")"
} | gzip -9n >"$doc/changelog.Debian.gz"
# What lintian reports but this package means, each with its reason.
install -m 0644 -D packaging/deb/lintian-overrides "$root/usr/share/lintian/overrides/qt-therapy"

# Maintainer scripts; every file under /etc is a conffile (an upgrade keeps local changes).
install -m 0755 packaging/deb/postinst packaging/deb/prerm packaging/deb/postrm "$root/DEBIAN/"
(cd "$root" && find etc -type f | sort | sed 's#^#/#') >"$root/DEBIAN/conffiles"

# Shared libraries the programs link, as Debian's tools name them.
shlibs_dir=$(mktemp -d)
mkdir -p "$shlibs_dir/debian"
printf 'Source: qt-therapy\n\nPackage: qt-therapy\nArchitecture: any\n' >"$shlibs_dir/debian/control"
shlibs=$(cd "$shlibs_dir" && dpkg-shlibdeps -O "$root"/usr/lib/qt-therapy/bin/* 2>/dev/null |
  sed -n 's/^shlibs:Depends=//p')
rm -rf "$shlibs_dir"
[ -n "$shlibs" ] || { echo "build.sh: dpkg-shlibdeps found no libraries" >&2; exit 1; }

cat >"$root/DEBIAN/control" <<CONTROL
Package: qt-therapy
Version: ${version}-${revision}
Architecture: ${arch}
Maintainer: ${maintainer}
Installed-Size: $(du -sk --exclude=DEBIAN "$root" | cut -f1)
Depends: ${shlibs}, adduser, init-system-helpers (>= 1.50), fonts-dejavu-core
Section: science
Priority: optional
Description: QTrobot personalised-behaviour suite for robot-assisted therapy
 ROS 2 nodes (over DDS, no ROS installation needed) that play an
 emotion-sequence memorisation game with a child on QTrobot: an engagement
 classifier on OpenFace features, user models, a Q-learning behaviour policy,
 the game manager, and the child's and therapist's tablet pages. Runs as
 qt-therapy.service; its Q-tables and recorded sessions stay in
 /var/lib/qt-therapy across upgrades.
CONTROL
(cd "$root" && find . -path ./DEBIAN -prune -o -type f -print | sed 's#^\./##' | sort |
  xargs md5sum) >"$root/DEBIAN/md5sums"

# The debug symbols, as dh_strip's automatic -dbgsym package (.ddeb): install it beside
# qt-therapy (same version) to get backtraces with function names, files and lines.
ln -s qt-therapy "$dbg/usr/share/doc/qt-therapy-dbgsym"
cat >"$dbg/DEBIAN/control" <<CONTROL
Package: qt-therapy-dbgsym
Source: qt-therapy
Version: ${version}-${revision}
Auto-Built-Package: debug-symbols
Architecture: ${arch}
Maintainer: ${maintainer}
Installed-Size: $(du -sk --exclude=DEBIAN "$dbg" | cut -f1)
Depends: qt-therapy (= ${version}-${revision})
Section: debug
Priority: optional
Description: debug symbols for qt-therapy
Build-Ids: ${build_ids[*]}
CONTROL
(cd "$dbg" && find . -path ./DEBIAN -prune -o -type f -print | sed 's#^\./##' | sort |
  xargs md5sum) >"$dbg/DEBIAN/md5sums"

dpkg-deb --root-owner-group "${deb_compression[@]}" --build "$root" "$out/$name.deb" >/dev/null
# Its sections are compressed already (--compress-debug-sections): xz would only take time.
dpkg-deb --root-owner-group -Zxz -z0 --build "$dbg" "$out/$(basename "$dbg").ddeb" >/dev/null
echo "$out/$(basename "$dbg").ddeb"
echo "$out/$name.deb"
