"""A run as an MCAP file of standard ROS 2 messages (``/tf``, ``/irring/points``, ``/map``,
``/truth/*``) for Foxglove and rosbag2 tools, written whole or not at all
(``outputs.atomic_file``); needs the ``mcap`` extra. Topics, frames and times:
docs/mapping.md.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..core import Cylinder, box_corners
from ..errors import OutputError
from ..outputs import MCAP_FILE, atomic_file

FRAME = "map"
ROBOT_FRAME = "base_link"

_SEP = "=" * 80

_TIME = "int32 sec\nuint32 nanosec"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id"
_QUATERNION = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1"
_POINT = "float64 x\nfloat64 y\nfloat64 z"


def _msgdef(main: str, *deps: tuple[str, str]) -> str:
    return "\n".join([main] + [f"{_SEP}\nMSG: {name}\n{text}" for name, text in deps])


_COMMON = (("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME))

MSGDEFS = {
    "sensor_msgs/msg/PointCloud2": _msgdef(
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\n"
        "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense",
        *_COMMON,
        ("sensor_msgs/PointField",
         "uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\n"
         "uint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\n"
         "string name\nuint32 offset\nuint8 datatype\nuint32 count")),
    "tf2_msgs/msg/TFMessage": _msgdef(
        "geometry_msgs/TransformStamped[] transforms",
        ("geometry_msgs/TransformStamped",
         "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform"),
        *_COMMON,
        ("geometry_msgs/Transform",
         "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation"),
        ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z"),
        ("geometry_msgs/Quaternion", _QUATERNION)),
    "nav_msgs/msg/OccupancyGrid": _msgdef(
        "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data",
        *_COMMON,
        ("nav_msgs/MapMetaData",
         "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\n"
         "uint32 height\ngeometry_msgs/Pose origin"),
        ("geometry_msgs/Pose", "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation"),
        ("geometry_msgs/Point", _POINT),
        ("geometry_msgs/Quaternion", _QUATERNION)),
    "geometry_msgs/msg/PolygonStamped": _msgdef(
        "std_msgs/Header header\ngeometry_msgs/Polygon polygon",
        *_COMMON,
        ("geometry_msgs/Polygon", "geometry_msgs/Point32[] points"),
        ("geometry_msgs/Point32", "float32 x\nfloat32 y\nfloat32 z")),
}

_FLOAT32 = 7
ROS_TIME_MAX_S = 2**31 - 1
CYLINDER_SIDES = 32


def _import():
    try:
        from mcap_ros2.writer import Writer   # deferred: optional (the mcap extra)
    except ImportError:
        raise ImportError("writing MCAP needs the mcap extra: pip install 'irring[mcap]' "
                          "(the mcap and mcap-ros2-support packages)") from None
    return Writer


def _stamp(t_ns: int) -> dict:
    return {"sec": int(t_ns // 1_000_000_000), "nanosec": int(t_ns % 1_000_000_000)}


def _header(t_ns: int) -> dict:
    return {"stamp": _stamp(t_ns), "frame_id": FRAME}


def _yaw_quaternion(yaw: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def point_cloud(points, t_ns: int) -> dict:
    """A PointCloud2 of one sweep's valid end points (x, y, z = 0, range; float32)."""
    valid = np.asarray(points.valid, bool)
    x = np.asarray(points.x, float)[valid]
    y = np.asarray(points.y, float)[valid]
    rng = np.asarray(points.d, float)[valid]
    cloud = np.zeros(x.size, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("range", "<f4")])
    cloud["x"], cloud["y"], cloud["range"] = x, y, rng
    fields = [{"name": n, "offset": 4 * i, "datatype": _FLOAT32, "count": 1}
              for i, n in enumerate(cloud.dtype.names)]
    return {"header": _header(t_ns), "height": 1, "width": int(x.size), "fields": fields,
            "is_bigendian": False, "point_step": cloud.itemsize,
            "row_step": cloud.itemsize * int(x.size), "data": cloud.tobytes(),
            "is_dense": True}


def occupancy_grid(grid, t_ns: int) -> dict:
    """The map as nav_msgs/OccupancyGrid: row-major from the origin cell, 0 … 100 % occupied,
    −1 for cells whose log-odds never moved."""
    lo = grid.log_odds
    data = np.round(100.0 / (1.0 + np.exp(-lo))).astype(np.int8)
    data[lo == 0] = -1
    ny, nx = grid.shape
    return {"header": _header(t_ns),
            "info": {"map_load_time": _stamp(t_ns), "resolution": float(grid.resolution_m),
                     "width": int(nx), "height": int(ny),
                     "origin": {"position": {"x": float(grid.origin_xy_m[0]),
                                             "y": float(grid.origin_xy_m[1]), "z": 0.0},
                                "orientation": _yaw_quaternion(0.0)}},
            "data": data.ravel().tolist()}


def _polygon(xy, t_ns: int) -> dict:
    return {"header": _header(t_ns),
            "polygon": {"points": [{"x": float(x), "y": float(y), "z": 0.0} for x, y in xy]}}


def _obstacle_outline(ob) -> np.ndarray:
    if isinstance(ob, Cylinder):
        a = np.linspace(0, 2 * np.pi, CYLINDER_SIDES, endpoint=False)
        return np.c_[ob.center_m[0] + ob.radius_m * np.cos(a),
                     ob.center_m[1] + ob.radius_m * np.sin(a)]
    return np.asarray(box_corners(ob))


def write_mcap(result, path) -> Path:
    """Write ``result`` (a :class:`pipeline.MapRun`) to ``path`` as MCAP (see the module doc).
    Raises ImportError naming the extra when the mcap packages are missing, OutputError
    (outputs.atomic_file) when ``path`` cannot be written or the sweeps' times overflow ROS time."""
    path = Path(path)
    with atomic_file(path, writes=MCAP_FILE) as tmp:
        write_mcap_to(result, tmp, path)
    return path


def write_mcap_to(result, tmp, path) -> None:
    """:func:`write_mcap`'s work without the rename: the MCAP written at ``tmp`` (a
    temporary the caller renames to ``path``, the name its errors give)."""
    Writer = _import()
    path = Path(path)
    t_ns, ends = 0, []
    for s in result.sweeps:
        t_ns += int(round(s.duration_s * 1e9))
        ends.append(t_ns)
    if t_ns // 1_000_000_000 > ROS_TIME_MAX_S:   # builtin_interfaces/Time's sec is an int32
        raise OutputError(f"{path}: the sweeps' hardware time adds up to "
                          f"{t_ns // 1_000_000_000} s, past the ROS 2 time stamp's "
                          f"{ROS_TIME_MAX_S} s (68 years); MCAP not written")
    with open(tmp, "wb") as f:
        writer = Writer(f)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        sc = result.scenario
        if sc is not None:
            writer.write_message("/truth/outline", schemas["geometry_msgs/msg/PolygonStamped"],
                                 _polygon(sc.room.outline_m, 0), log_time=0, publish_time=0)
            for ob in sc.obstacles:
                writer.write_message("/truth/obstacles",
                                     schemas["geometry_msgs/msg/PolygonStamped"],
                                     _polygon(_obstacle_outline(ob), 0), log_time=0,
                                     publish_time=0)
        for k, (sweep, points, t) in enumerate(zip(result.sweeps, result.points, ends)):
            x, y, yaw = (float(v) for v in np.asarray(sweep.pose, float)[:3])
            tf = {"transforms": [{"header": _header(t), "child_frame_id": ROBOT_FRAME,
                                  "transform": {"translation": {"x": x, "y": y, "z": 0.0},
                                                "rotation": _yaw_quaternion(yaw)}}]}
            writer.write_message("/tf", schemas["tf2_msgs/msg/TFMessage"], tf, log_time=t,
                                 publish_time=t, sequence=k)
            writer.write_message("/irring/points", schemas["sensor_msgs/msg/PointCloud2"],
                                 point_cloud(points, t), log_time=t, publish_time=t,
                                 sequence=k)
        writer.write_message("/map", schemas["nav_msgs/msg/OccupancyGrid"],
                             occupancy_grid(result.grid, t_ns), log_time=t_ns,
                             publish_time=t_ns)
        writer.finish()
