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


def detected_object_markers(scene, ids: Sequence[int], chosen_id: int, stamp, frame_id: str):
    """``visualization_msgs/MarkerArray`` of one frame's objects for rviz: each one's measured
    shape at its pose (the chosen one green, the others blue), its id and kind above it, and each
    refused piece as a red sphere with its reason. Markers live 0.5 s: a frame that no longer
    shows an object leaves no ghost of it."""
    import rospy
    from visualization_msgs.msg import Marker, MarkerArray

    lifetime = rospy.Duration(0.5)
    markers = [Marker(action=Marker.DELETEALL)]

    def marker(kind: int, namespace: str, number: int, rgba: Tuple[float, float, float, float]) -> Marker:
        item = Marker(type=kind, action=Marker.ADD, ns=namespace, id=number, lifetime=lifetime)
        item.header.stamp, item.header.frame_id = stamp, frame_id
        item.color.r, item.color.g, item.color.b, item.color.a = rgba
        item.pose.orientation.w = 1.0
        return item

    for track_id, found in zip(ids, scene.objects):
        detection, shape = found.detection, found.detection.shape
        chosen = track_id == chosen_id
        rgba = (0.15, 0.85, 0.25, 0.8) if chosen else (0.2, 0.45, 0.95, 0.6)
        body = marker(Marker.CYLINDER if detection.kind == "cylinder" else Marker.CUBE, "detected", track_id, rgba)
        x, y, z = detection.position_table
        body.pose.position.x, body.pose.position.y, body.pose.position.z = x, y, z
        orientation = body.pose.orientation
        orientation.x, orientation.y, orientation.z, orientation.w = quaternion_of_yaw(detection.yaw)
        if shape is not None:
            body.scale.x, body.scale.y, body.scale.z = shape.size
        else:
            body.scale.x = body.scale.y = body.scale.z = max(detection.size, 0.01)
        text = marker(Marker.TEXT_VIEW_FACING, "detected_label", track_id, (1.0, 1.0, 1.0, 1.0))
        text.pose.position.x, text.pose.position.y = x, y
        text.pose.position.z = z + 0.5 * body.scale.z + 0.03
        text.scale.z = 0.025
        text.text = f"{'> ' if chosen else ''}{track_id} {found.label}"
        markers += [body, text]
    for number, piece in enumerate(scene.refused):
        sphere = marker(Marker.SPHERE, "refused", number, (0.95, 0.15, 0.1, 0.8))
        sphere.pose.position.x, sphere.pose.position.y, sphere.pose.position.z = piece.position_table
        sphere.scale.x = sphere.scale.y = sphere.scale.z = 0.02
        text = marker(Marker.TEXT_VIEW_FACING, "refused_label", number, (0.95, 0.3, 0.2, 1.0))
        text.pose.position.x, text.pose.position.y = piece.position_table[0], piece.position_table[1]
        text.pose.position.z = piece.position_table[2] + 0.04
        text.scale.z = 0.02
        text.text = piece.reason.name
        markers += [sphere, text]
    return MarkerArray(markers=markers)
