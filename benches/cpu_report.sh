#!/bin/sh
# Prints the CPU engine's measured times and their ratios to references measured in the same run.
set -e
cd "$(dirname "$0")/.."
exec cargo run --release --example cpu_report
