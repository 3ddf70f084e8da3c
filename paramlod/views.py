"""Camera sets for ``paramlod.render_views``: ``stereo``, ``cube_faces`` + ``equirect``, ``quilt`` +
``quilt_image`` (the public face of paramlod.core.views)."""
from paramlod.core.views import MAX_VIEWS, Views, cube_faces, equirect, quilt, quilt_image, stereo, strip_image

__all__ = ["MAX_VIEWS", "Views", "stereo", "cube_faces", "equirect", "quilt", "quilt_image", "strip_image"]
