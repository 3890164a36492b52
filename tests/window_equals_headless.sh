#!/usr/bin/env bash
# window_equals_headless.sh XVFB_RUN FLAG PROGRAM ARGS...: runs PROGRAM ARGS --headless FLAG a.png,
# then PROGRAM ARGS FLAG b.png in a window under Xvfb; passes when both exit 0 and the two final
# frames are the same file byte for byte (the window plays the same input through the same
# schedule as the headless run).
set -u
xvfb=$1
flag=$2
shift 2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
if ! "$@" --headless "$flag" "$dir/headless.png"; then
  echo "window_equals_headless: the headless run failed" >&2
  exit 1
fi
if ! "$xvfb" -a "$@" "$flag" "$dir/window.png"; then
  echo "window_equals_headless: the windowed run failed" >&2
  exit 1
fi
if ! cmp "$dir/headless.png" "$dir/window.png"; then
  echo "window_equals_headless: the windowed run's last frame differs from the headless one" >&2
  exit 1
fi
echo "window_equals_headless: same last frame ($(stat -c %s "$dir/window.png") bytes)"
