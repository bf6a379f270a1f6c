#!/bin/sh
# The system packages the tests need (README "Set up a fresh machine"): Debian's chromium and chromedriver (browser
# tests), espeak-ng (speech of the sound tests), nginx and caddy (reverse-proxy tests) and the PostgreSQL 15 server
# binaries (initdb, pg_ctl, pg_dump, pg_restore: the tests' own throwaway server, the restart and backup tests), and
# Mesa's EGL and drivers (libegl1, libegl-mesa0, libgl1-mesa-dri: the mesh style's OpenGL without a display, on the
# CPU through llvmpipe where there is no GPU).
# Idempotent and quiet: it does nothing when all are there, installs what is missing with apt-get (through sudo when
# not root), and without apt-get says what to install and exits 1.
set -eu
have() { command -v "$1" >/dev/null 2>&1 || [ -x "/usr/sbin/$1" ] || [ -x "/usr/bin/$1" ]; }
missing=""
have chromium || missing="$missing chromium"
have chromedriver || missing="$missing chromium-driver"
have espeak-ng || missing="$missing espeak-ng"
have nginx || missing="$missing nginx"
have caddy || missing="$missing caddy"
for tool in initdb pg_ctl pg_dump pg_restore; do
  [ -x "/usr/lib/postgresql/15/bin/$tool" ] || { missing="$missing postgresql-15"; break; }
done
egl_ok=1
for lib in libEGL.so.1 libEGL_mesa.so.0; do ldconfig -p 2>/dev/null | grep -q "$lib" || egl_ok=0; done
ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || egl_ok=0
[ "$egl_ok" -eq 1 ] || missing="$missing libegl1 libegl-mesa0 libgl1-mesa-dri"
[ -z "$missing" ] && exit 0
if ! command -v apt-get >/dev/null 2>&1; then
  echo "error: no apt-get here: install these packages (Debian names) with your package manager:$missing" >&2
  echo "       (PostgreSQL 15's server binaries are looked for in /usr/lib/postgresql/15/bin)" >&2
  exit 1
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
# shellcheck disable=SC2086  # the package list is meant to split
$sudo apt-get install -y -q $missing >/dev/null 2>&1 \
  || { $sudo apt-get update -q >/dev/null && $sudo apt-get install -y -q $missing >/dev/null; }
