"""Publishing a fleet's trees as C2SP tlog-tiles (``publish``): the tile cutter (``tiler``),
the published folder's files (``files``) and the command's one call (``publish_root``)."""

from trace_audit.publish.publish import Progress, PublishReport, RobotPublish, publish_root

__all__ = ["Progress", "PublishReport", "RobotPublish", "publish_root"]
