"""Where the completion method's model files are: the shipped ones in the package, or a user's path."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

#: The shipped model (``completion/models/small.safetensors`` in the package); only the current one ships.
DEFAULT_MODEL = "small"


def beside(model, suffix: str) -> Path:
    """A file beside a model file that belongs to it: ``<model stem><suffix>`` (``small.safetensors`` ->
    ``small<suffix>``)."""
    model = Path(model)
    return model.with_name(model.name.removesuffix(".safetensors") + suffix)


def shipped_model(name: str = DEFAULT_MODEL) -> Path:
    """Path of a model that ships in the package: ``colonbench/completion/models/<name>.safetensors``."""
    return Path(str(resources.files("colonbench.completion").joinpath(f"models/{name}.safetensors")))


def shipped_models() -> list[str]:
    """Names of the models that ship in the package."""
    folder = resources.files("colonbench.completion").joinpath("models")
    return sorted(p.name[: -len(".safetensors")] for p in folder.iterdir() if p.name.endswith(".safetensors"))


def model_path(model=None) -> Path:
    """A model file: ``None`` is the default shipped model, a shipped model's name its file, else a path."""
    if model is None:
        return shipped_model()
    path = Path(model)
    if not path.exists() and path.suffix != ".safetensors" and str(model) in shipped_models():
        return shipped_model(str(model))
    return path
