#!/usr/bin/env bash
# Build the offline sandbox base image for machines that cannot reach a container registry.
#
# It is the equivalent of `python:3.11-slim-bookworm`: a minimal Debian bookworm root file
# system bootstrapped from the Debian mirror this machine is configured with, plus Debian's own
# Python 3.11 (with venv), imported into Docker as ${RIVET_SANDBOX_BASE_TAG}.
#
# Usage: bash sandbox/build_base.sh [--force]
# Environment: RIVET_SANDBOX_BASE_TAG (default rivet-sandbox-base:bookworm),
#              RIVET_DEBIAN_MIRROR (default: read from /etc/apt/sources.list{,.d/*}).
set -euo pipefail

TAG="${RIVET_SANDBOX_BASE_TAG:-rivet-sandbox-base:bookworm}"
SUITE=bookworm
FORCE=0
[[ "${1:-}" == "--force" ]] && FORCE=1

say() { echo "sandbox-base: $*" >&2; }
die() {
	echo "sandbox-base: error: $*" >&2
	exit 1
}

# The first Debian (not security) mirror that serves $SUITE, from deb822 or one-line sources.
detect_mirror() {
	local f uri
	for f in /etc/apt/sources.list.d/*.sources; do
		[[ -r "$f" ]] || continue
		uri=$(awk -v suite="$SUITE" '
			/^[[:space:]]*$/ { if (u != "" && s ~ suite && u !~ /security/) { print u; exit } u = ""; s = ""; next }
			/^URIs:/ { u = $2 } /^Suites:/ { s = $0 }
			END { if (u != "" && s ~ suite && u !~ /security/) print u }' "$f" | head -n1)
		[[ -n "$uri" ]] && { echo "$uri"; return; }
	done
	for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
		[[ -r "$f" ]] || continue
		uri=$(awk -v suite="$SUITE" '$1 == "deb" && $3 == suite && $2 !~ /security/ { print $2; exit }' "$f")
		[[ -n "$uri" ]] && { echo "$uri"; return; }
	done
	echo "http://deb.debian.org/debian"
}

command -v docker >/dev/null || die "the docker CLI is missing: apt-get install docker.io (or run 'make system')"
docker info >/dev/null 2>&1 || die "the Docker engine is not reachable: start it ('make system', or 'dockerd &' as root)"

if [[ $FORCE -eq 0 ]] && docker image inspect "$TAG" >/dev/null 2>&1; then
	say "$TAG already exists (use --force to rebuild)"
	exit 0
fi

[[ $(id -u) -eq 0 ]] || die "debootstrap needs root: run 'sudo make sandbox-base'"
command -v debootstrap >/dev/null || die "debootstrap is missing: apt-get install debootstrap (or run 'make system')"

MIRROR="${RIVET_DEBIAN_MIRROR:-$(detect_mirror)}"
SECURITY="${MIRROR%/debian}/debian-security"
ROOTFS=$(mktemp -d /var/tmp/rivet-sandbox-base.XXXXXX)
trap 'rm -rf --one-file-system "$ROOTFS"' EXIT

say "bootstrapping Debian $SUITE (minbase + python3) from $MIRROR into $ROOTFS"
start=$(date +%s)
debootstrap --variant=minbase --components=main \
	--include=python3,python3-venv,ca-certificates \
	"$SUITE" "$ROOTFS" "$MIRROR" >&2

say "configuring apt sources and slimming the root file system"
rm -f "$ROOTFS/etc/apt/sources.list"
cat >"$ROOTFS/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $MIRROR
Suites: $SUITE $SUITE-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: $SECURITY
Suites: $SUITE-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
# Like the official slim images: no docs, man pages or translations in later apt installs.
cat >"$ROOTFS/etc/dpkg/dpkg.cfg.d/docker-slim" <<'EOF'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
EOF
chroot "$ROOTFS" apt-get clean
rm -rf "$ROOTFS"/var/lib/apt/lists/* "$ROOTFS"/var/cache/apt/*.bin "$ROOTFS"/var/log/*.log \
	"$ROOTFS"/usr/share/doc/* "$ROOTFS"/usr/share/man/* "$ROOTFS"/usr/share/locale/*
"$ROOTFS/usr/bin/python3" -c 'import sys, venv; assert sys.version_info[:2] == (3, 11), sys.version' ||
	die "the bootstrapped python3 is not 3.11"

say "importing into Docker as $TAG"
tar --numeric-owner -C "$ROOTFS" --exclude='./dev/*' --exclude='./proc/*' --exclude='./sys/*' -c . |
	docker import \
		--change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
		--change 'ENV LANG=C.UTF-8' \
		--change 'LABEL rivet.sandbox.base=debootstrap' \
		--change "LABEL rivet.sandbox.base.mirror=$MIRROR" \
		--change 'CMD ["python3"]' \
		- "$TAG" >/dev/null
say "built $TAG in $(($(date +%s) - start)) s"
