"""Perception: pure numpy, no ROS (the detector node and the benches build on it).

- :mod:`.camera_model`: the pinhole camera model;
- :mod:`.images`: image and CameraInfo decoding, the per-frame input checks;
- :mod:`.morphology`: connected components, dilation;
- :mod:`.detector`: the object detector, its settings and its answers (Detection, Refusal);
- :mod:`.tracker`: the tracker through occlusion and in the hand, with its explicit state;
- :mod:`.overlay`: the debug image drawn for people.
"""
