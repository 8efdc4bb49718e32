"""Encodings: a record's canonical bytes and digests (``codec``), messages assembled into
cycles by the chain (``cycles``), a layer read with only the fields one use needs
(``partial``), whether a cycle matches its seal (``seal_check``), and MCAP's bytes: record
framing (``mcap_records``), the summary's records (``mcap_summary``), one chunk
(``mcap_chunks``), chunks read on demand (``mcap_chunk_reader``), the chunk table
(``mcap_table``) and one file (``mcap_file``).

Stands on the ground (records, errors, read limits); imports nothing that reads segments.
"""
