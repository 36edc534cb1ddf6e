"""Image-side vision for the operator: edge snapping, automatic edge matching, model-based tracking.

* ``profiles``: the 1D edge search along normals that snapping and tracking share;
* ``snap``: a clicked segment refined to the image's edge (``snap_segment``);
* ``track``: a model-based edge tracker (``EdgeTracker``) that follows a known object in a video;
* ``matching``: clicked image edges assigned to model edges automatically (``match_edges``).

OpenCV and image arrays live here (app/); the pose geometry they call is in core/.
"""
