"""The pipelines behind the command line, callable from a script or a notebook with an options
object: what ``jaxrod michell``, ``analyze``, ``trefoil`` / ``knot`` (the twist study and its
accuracy mode), ``atlas`` and ``helix`` run, with the files they write. The command line only
parses its arguments into these options and prints what they return."""
from .accuracy import AccuracyRun, accuracy_levels, run_accuracy, write_convergence_csv
from .analyze import AnalysedRod, AnalyzeOptions, analyze_files, write_analysis_files
from .atlas import AtlasOptions, atlas_cases_of, atlas_json, run_atlas_study, write_atlas_summary
from .helix import HelixCase, HelixRun, SolvedHelixRoot, helix_case, run_helix
from .helix_files import write_helix_files
from .michell import MICHELL_MIN_NODES, MichellOptions, MichellRun, michell_json, run_michell, write_michell_files
from .trefoil import (KnotStudyOptions, KnotStudyRun, check_knot_memory, check_resumable, critical_json,
                      run_knot_study, study_scene)
from .workers import Workers

__all__ = ["AccuracyRun", "accuracy_levels", "run_accuracy", "write_convergence_csv", "AnalysedRod", "AnalyzeOptions",
           "analyze_files", "write_analysis_files", "AtlasOptions", "atlas_cases_of", "atlas_json", "run_atlas_study",
           "write_atlas_summary", "HelixCase", "HelixRun", "SolvedHelixRoot", "helix_case", "run_helix",
           "write_helix_files", "MICHELL_MIN_NODES", "MichellOptions", "MichellRun", "michell_json", "run_michell",
           "write_michell_files", "KnotStudyOptions", "KnotStudyRun", "check_knot_memory", "check_resumable",
           "critical_json", "run_knot_study", "study_scene", "Workers"]
