"""`python tests/two_node_cluster.py`: a two-node Ray cluster on this machine (Ray's cluster_utils, one
CPU per node) for tests. Prints one JSON line {"address": ..., "node_ids": [...]}, then holds the cluster
until its stdin closes and shuts it down. A separate process, so that the test process's own Ray is
untouched (Cluster.shutdown resets this process's Ray globals)."""

from __future__ import annotations

import json
import os
import sys

os.environ.setdefault("RAY_AUTH_MODE", "disabled")

from ray.cluster_utils import Cluster  # noqa: E402

if __name__ == "__main__":
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    try:
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        nodes = [node.node_id for node in cluster.list_all_nodes()]
        print(json.dumps({"address": cluster.address, "node_ids": nodes}), flush=True)
        sys.stdin.read()  # until the test closes it
    finally:
        cluster.shutdown()
