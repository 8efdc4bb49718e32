"""The Foxglove view of a log: what a decision looks like in Foxglove (``view``: scene
updates, decision logs and plot channels in ``foxglove-sdk``'s own types), written to a file
with the TRACE channels copied through (``export``: ``export --format foxglove``), and served
live over the SDK's WebSocket server (``live``: ``tail --foxglove``). docs/foxglove.md.
"""
