"""One decision as an investigator reads it, and its causal graph and counterfactual tree.

``decision`` holds the ``Decision`` view model and ``read_decision`` (a logged cycle read
leniently, optional fields at their schema defaults, ``defaults``); ``graph`` builds the
causal graph and the counterfactual tree from it and the chains ``trace_audit.chains``
walked. ``lenient`` is the one owner of reading untrusted JSON leniently, for these and
every reader above them (its two meanings of "a number" named: ``as_float``,
``as_number_or_flag``).
"""

from __future__ import annotations

from trace_audit.causal.decision import (
    AlternativeView,
    ChannelView,
    CheckView,
    CounterfactualView,
    Decision,
    ExecutionView,
    FactorValue,
    TreeEdgeView,
    TreeNodeView,
    TreeView,
    format_value,
    read_decision,
)
from trace_audit.causal.defaults import layer_with_defaults
from trace_audit.causal.graph import (
    ACTION_NODE,
    EdgeData,
    GraphAttributes,
    GraphData,
    NodeData,
    causal_graph,
    causal_graph_data,
    graph_data,
    tree_graph,
    tree_graph_data,
)

__all__ = [
    "ACTION_NODE",
    "AlternativeView",
    "ChannelView",
    "CheckView",
    "CounterfactualView",
    "Decision",
    "EdgeData",
    "ExecutionView",
    "FactorValue",
    "GraphAttributes",
    "GraphData",
    "NodeData",
    "TreeEdgeView",
    "TreeNodeView",
    "TreeView",
    "causal_graph",
    "causal_graph_data",
    "format_value",
    "graph_data",
    "layer_with_defaults",
    "read_decision",
    "tree_graph",
    "tree_graph_data",
]
