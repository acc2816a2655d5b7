"""Segment: the object mask of a 48x48 frame, fg(MOG2 background model) AND NOT the U-Net's
robot mask (paper appendix "Segmentation").

    mog2         OpenCV's BackgroundSubtractorMOG2 in jnp, bit-exact with cv2
    mog2_parity  the cv2 comparison the tests and benchmarks share
    unet         the appendix's U-Net (robot mask)
    pipeline     fit, segment, segmented_image, evaluate, save / load
    __main__     the command: fit and evaluate one task (roll-segmentation)
"""

from roll_jax.common.lazy import lazy_api

__all__, __getattr__, __dir__ = lazy_api(__name__, {
    ".pipeline": ("SegParams", "fit", "segment", "segmented_image", "evaluate", "save",
                  "load"),
})
