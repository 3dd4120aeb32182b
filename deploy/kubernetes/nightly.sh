#!/bin/bash
# Runs one nightly reprocessing on Kubernetes: the Indexed Job of shards,
# then, once every index completed, the commit Job.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
kubectl delete job tirewear-shards tirewear-commit --ignore-not-found
kubectl apply -f "$here/shards-job.yaml"
kubectl wait --for=condition=complete --timeout="${TIMEOUT:-6h}" job/tirewear-shards
kubectl apply -f "$here/commit-job.yaml"
kubectl wait --for=condition=complete --timeout=1h job/tirewear-commit
kubectl logs job/tirewear-commit
