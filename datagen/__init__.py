"""colonbench.datagen: procedural and real colons, the virtual camera, holes, segments and samples."""

#: The hole models a sample can be made with (:mod:`colonbench.datagen.holes`).
HOLE_MODELS = ("camera", "spheres", "camera+spheres", "camera+end", "spheres+end", "camera+spheres+end", "video")
