"""colonbench.video: synthetic colonoscopy video and the reconstructions made from it.

- :mod:`~colonbench.video.withdrawal`: the scope's camera model and its withdrawal through a colon, depth and
  visibility cast per frame;
- :mod:`~colonbench.video.mucosa`: the mucosa's texture and the scope's own light, rendered with pyrender;
- :mod:`~colonbench.video.framedata`: frame datasets on disk (``colonbench video``);
- :mod:`~colonbench.video.fusion`: the ``video`` hole model, frames degraded as a real pipeline's and fused by
  TSDF into a reconstruction-like partial surface.

Importing this package registers the ``video`` hole model with the generator
(:func:`colonbench.datagen.sample.register_partial_maker`); dataset generation and ``colonbench segments`` do.
"""

from colonbench.datagen.sample import register_partial_maker


def _video_partial(*args, **kwargs):
    from colonbench.video.fusion import video_partial

    return video_partial(*args, **kwargs)


register_partial_maker("video", _video_partial)
