"""Model layer: parse and validate robot, error-model and measurement files."""
from gecgen.model.errors import Coefficient, ErrorModel, Term, load_error_model
from gecgen.model.robot import ERROR_NAMES, WRENCH, Joint, Robot
from gecgen.model.robot_file import load_robot
from gecgen.model.validation import ModelError

__all__ = ["Coefficient", "ERROR_NAMES", "ErrorModel", "Joint", "ModelError", "Robot", "Term", "WRENCH",
           "load_error_model", "load_robot"]
