"""Encodings: a record's canonical bytes and digests (``codec``), MCAP's bytes (record framing
``mcap_records``, one chunk ``mcap_chunks``, one file ``mcap_file``), messages assembled into
cycles by the chain (``cycles``), a layer read with only the fields one use needs
(``partial``), and whether a cycle matches its seal (``seal_check``).

Stands on the ground (records, errors, read limits); imports nothing that reads segments.
"""
