"""An object's shape on ROS: ``shape_msgs/SolidPrimitive`` to and from :class:`~fr5_rl.objects.ObjectShape`.

The simulator node and the detector publish what they know of the object on ``/target_shape``;
the policy node reads it there. A primitive's dimensions are along the frame of the object's pose
on ``/target_pose``: a BOX's ``[x, y, z]`` (m), a CYLINDER's ``[height, radius]`` (m). A box whose
y side is its longer one is the same box turned a quarter (:func:`~fr5_rl.objects.shape_from_extents`).
"""
from __future__ import annotations

from typing import Sequence, Tuple

from shape_msgs.msg import SolidPrimitive

from ..objects import ObjectShape, quaternion_of_yaw, shape_from_extents


def primitive_from_shape(shape: ObjectShape) -> SolidPrimitive:
    """The primitive of ``shape`` (its own frame: a box's longer top side along x)."""
    if shape.kind == "cylinder":
        dimensions = [0.0, 0.0]
        dimensions[SolidPrimitive.CYLINDER_HEIGHT] = shape.size[2]
        dimensions[SolidPrimitive.CYLINDER_RADIUS] = shape.size[0] / 2.0
        return SolidPrimitive(type=SolidPrimitive.CYLINDER, dimensions=dimensions)
    return SolidPrimitive(type=SolidPrimitive.BOX, dimensions=list(shape.size))


def shape_from_primitive(message: SolidPrimitive) -> Tuple[ObjectShape, float]:
    """The shape a primitive describes, and the turn (rad) from its frame's x axis to the shape's.

    :raises ValueError: a type other than BOX or CYLINDER, or dimensions that are not positive
        lengths (the message says which).
    """
    dimensions = [float(value) for value in message.dimensions]
    if message.type == SolidPrimitive.BOX:
        if len(dimensions) != 3:
            raise ValueError(f"a BOX has 3 dimensions (x, y, z in m), got {dimensions}")
        return shape_from_extents("box", dimensions)
    if message.type == SolidPrimitive.CYLINDER:
        if len(dimensions) != 2:
            raise ValueError(f"a CYLINDER has 2 dimensions (height, radius in m), got {dimensions}")
        diameter = 2.0 * dimensions[SolidPrimitive.CYLINDER_RADIUS]
        return shape_from_extents("cylinder", (diameter, diameter, dimensions[SolidPrimitive.CYLINDER_HEIGHT]))
    raise ValueError(f"a SolidPrimitive of type {message.type}: the policy handles boxes ({SolidPrimitive.BOX}) "
                     f"and cylinders ({SolidPrimitive.CYLINDER})")


def detected_objects_message(scene, ids: Sequence[int], stamp, frame_id: str):
    """``fr5_rl/DetectedObjects`` of one frame's :class:`~fr5_rl.perception.scene_detector.SceneDetection`:
    each object's id (``ids``, in the order of ``scene.objects``), its centre upright at its yaw
    and its shape, each refused piece's reason and place, in ``frame_id`` (the table frame the
    detector measures in) at ``stamp`` (the image's)."""
    from ..msg import DetectedObject, DetectedObjects, RefusedPiece

    message = DetectedObjects()
    message.header.stamp, message.header.frame_id = stamp, frame_id
    for track_id, found in zip(ids, scene.objects):
        detection = found.detection
        item = DetectedObject(id=track_id, kind=found.label)
        position, orientation = item.pose.position, item.pose.orientation
        position.x, position.y, position.z = detection.position_table
        orientation.x, orientation.y, orientation.z, orientation.w = quaternion_of_yaw(detection.yaw)
        if detection.shape is not None:
            item.shape = primitive_from_shape(detection.shape)
        message.objects.append(item)
    for piece in scene.refused:
        refused = RefusedPiece(reason=piece.reason.name, detail=piece.detail)
        refused.position.x, refused.position.y, refused.position.z = piece.position_table
        message.refused.append(refused)
    return message
