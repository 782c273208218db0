#!/bin/sh
# Prints the CPU engine's measured times and their ratios to references measured in the same run.
set -e
cd "$(dirname "$0")/.."
exec cargo bench --bench cpu_report
