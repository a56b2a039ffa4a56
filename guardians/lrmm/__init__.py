"""Learned risk metric maps: the model (numpy inference, artifact I/O), training, the guardian."""

from rmm_guardians.lrmm.model import LRMMModel, default_model_path, load_model

__all__ = ["LRMMModel", "default_model_path", "load_model"]
