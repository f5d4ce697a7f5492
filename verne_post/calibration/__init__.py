"""Kinematic calibration of the VERNE (``verne-post calibrate``): identify the machine file's
geometry and joint zero offsets from measured tool-tip positions.

Stages, each its own module: :mod:`.measurements` (reading and checking the CSV),
:mod:`.model` (the forward-kinematics prediction and its analytic Jacobian, pure),
:mod:`.fit` (least squares with a prior, outliers, covariance, pure), :mod:`.directions`
(what the measurements determine and what not, in words, pure), :mod:`.plan` (D-optimal
measurement poses, pure), :mod:`.output` (the calibrated machine file, ruamel.yaml round trip)
and :mod:`.report` (JSON and HTML). Units at the interface mm and degrees; inside, mm and rad;
tips in the table frame.
"""

from .fit import Calibration, FitError, calibrate
from .measurements import Measurements, read_measurements
from .model import PARAMETERS, Poses, parameters_of, predict
from .output import calibrated_text
from .plan import Plan, Volume, parse_volume, plan_poses
from .report import report_data, report_html, report_json

__all__ = ["PARAMETERS", "Calibration", "FitError", "Measurements", "Plan", "Poses", "Volume", "calibrate",
           "calibrated_text", "parameters_of", "parse_volume", "plan_poses", "predict", "read_measurements",
           "report_data", "report_html", "report_json"]
