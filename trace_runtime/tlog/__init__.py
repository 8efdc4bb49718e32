"""The transparency log a robot's seals form: its RFC 6962 Merkle tree (``merkle``), C2SP
signed notes, checkpoints and cosignatures (``signed_note``), Ed25519 keys (``keys``),
checkpoint records (``checkpoints``), and the witness seen from the robot's side: the HTTP
client that submits checkpoints (``witness_client``) and the store of the cosigned notes it
brought back (``cosignature_store``).
"""
