"""Skeleton documents rebuilt from the instruction events' deltas."""

from __future__ import annotations

from typing import Any

Yarns = dict[int, dict[str, list[Any]]]


def yarns_of(document: dict[str, Any]) -> Yarns:
    """The yarns of a skeleton JSON document: id -> node ids and coordinates."""
    return {
        y["id"]: {"node_ids": list(y["node_ids"]), "nodes": [list(p) for p in y["nodes"]]}
        for y in document["yarns"]
    }


def apply_delta(yarns: Yarns, delta: dict[str, Any]) -> None:
    """Apply one instruction event's ``skeleton`` delta in place."""
    for node in delta["inserted"]:
        yarn = yarns[node["yarn"]]
        at = 0 if node["after"] == -1 else yarn["node_ids"].index(node["after"]) + 1
        yarn["node_ids"].insert(at, node["node"])
        yarn["nodes"].insert(at, list(node["xyz"]))
    for node in delta["moved"]:
        yarn = yarns[node["yarn"]]
        yarn["nodes"][yarn["node_ids"].index(node["node"])] = list(node["xyz"])
    for new in delta["new_yarns"]:
        assert new["id"] not in yarns
        yarns[new["id"]] = {
            "node_ids": list(new["node_ids"]),
            "nodes": [list(p) for p in new["nodes"]],
        }
