"""sensor_msgs/Image and CameraInfo from numpy arrays and a pinhole model, without cv_bridge."""
from __future__ import annotations

import numpy as np
import rospy
from sensor_msgs.msg import CameraInfo, Image

from ..perception.camera_model import Intrinsics


def image_message(array: np.ndarray, encoding: str, stamp: rospy.Time, frame_id: str) -> Image:
    """A sensor_msgs/Image of an (H, W[, C]) array, little-endian, rows packed."""
    message = Image(height=array.shape[0], width=array.shape[1], encoding=encoding, is_bigendian=0)
    message.header.stamp, message.header.frame_id = stamp, frame_id
    message.step = array.shape[1] * (array.shape[2] if array.ndim == 3 else 1) * array.dtype.itemsize
    message.data = array.tobytes()  # one copy, C order, whatever the array's strides
    return message


def camera_info_message(intrinsics: Intrinsics, stamp: rospy.Time, frame_id: str) -> CameraInfo:
    """The CameraInfo of a distortion-free pinhole camera."""
    info = CameraInfo(width=intrinsics.width, height=intrinsics.height, distortion_model="plumb_bob")
    info.header.stamp, info.header.frame_id = stamp, frame_id
    info.D = [0.0] * 5
    info.K = intrinsics.k()
    info.R = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    info.P = intrinsics.p()
    return info
