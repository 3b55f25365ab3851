"""chewbot: kinematics, inverse dynamics and inertia coupling of the bio-inspired chewing robot."""

from chewbot.errors import ChewbotError, KinematicsError, ParameterError, TaskError
from chewbot.model import Model
from chewbot.params import BUILTIN_MODELS, load_model

__version__ = "0.1.0"

__all__ = ["BUILTIN_MODELS", "ChewbotError", "KinematicsError", "Model", "ParameterError", "TaskError", "load_model", "__version__"]
