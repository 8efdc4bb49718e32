"""A rosbag2 recorder for the tests, run as its own process as ``ros2 bag record`` runs.

    python tests/rosbag_recorder.py BAG --splits N --messages M [--hz H] [--size B] [--start-ns T]

Writes ``BAG/<name>_<k>.mcap`` split files and ``metadata.yaml`` with the ``rosbags``
library (CDR messages, ``ros2msg`` schemas), not with anything of this project: two topics,
``/scan`` (``std_msgs/msg/String`` of ``--size`` bytes, the one a robot cites) and
``/odom`` (a small uncited one). With ``--hz`` it writes in real time, so a logger beside it
follows a recording that grows; each split is written in place, so the newest file grows
under its readers (``--splits 1`` writes ``BAG/<name>.mcap`` as rosbags names it).
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

STORE = get_typestore(Stores.ROS2_HUMBLE)
TEXT = "std_msgs/msg/String"


def cdr(text: str) -> bytes:
    """The CDR bytes of a ``std_msgs/msg/String`` (what rclpy's serialize_message gives)."""
    return bytes(STORE.serialize_cdr(STORE.types[TEXT](data=text), TEXT))


def scan_text(i: int, size: int) -> str:
    return f"scan {i} ".ljust(size, "x")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("bag", type=Path)
    parser.add_argument("--splits", type=int, default=1)
    parser.add_argument("--messages", type=int, default=40)
    parser.add_argument("--hz", type=float, default=0.0)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--start-ns", type=int, default=1_000_000_000)
    args = parser.parse_args()
    bag: Path = args.bag
    per_split = -(-args.messages // args.splits)
    period_ns = 50_000_000
    for k in range(args.splits):
        # rosbags writes one file per bag folder: each split is its own bag, whose file is
        # then named and placed as rosbag2 names a split (``<bag>_<k>.mcap``)
        folder = bag if args.splits == 1 else bag.with_name(f"{bag.name}.split{k}")
        with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            scan = writer.add_connection("/scan", TEXT, typestore=STORE)
            odom = writer.add_connection("/odom", TEXT, typestore=STORE)
            for i in range(k * per_split, min(args.messages, (k + 1) * per_split)):
                t_ns = args.start_ns + i * period_ns
                writer.write(scan, t_ns, cdr(scan_text(i, args.size)))
                writer.write(odom, t_ns + 1_000_000, cdr(f"odom {i}"))
                if args.hz:
                    time.sleep(1 / args.hz)
        if args.splits > 1:
            bag.mkdir(exist_ok=True)
            (folder / f"{folder.name}.mcap").rename(bag / f"{bag.name}_{k}.mcap")
            shutil.move(folder / "metadata.yaml", bag / "metadata.yaml")
            folder.rmdir()
    print("recorded", flush=True)


if __name__ == "__main__":
    main()
