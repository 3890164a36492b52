#!/usr/bin/env bash
# expect_exit.sh CODE TEXT PROGRAM ARGS...: runs the program, passes when it exits with CODE and
# its output (stdout and stderr) contains TEXT.
set -u
code=$1
text=$2
shift 2
output=$("$@" 2>&1)
status=$?
printf '%s\n' "$output"
if [[ $status -ne $code ]]; then
  echo "expect_exit: exit status $status, expected $code" >&2
  exit 1
fi
if [[ $output != *"$text"* ]]; then
  echo "expect_exit: output lacks '$text'" >&2
  exit 1
fi
