"""Studies: reproducible experiments that write a report a person can open.

``discover()`` finds every module here that defines ``STUDY`` (see ``base``);
``run_studies`` runs some of them and writes ``index.html`` plus data files.

>>> from nonholo.studies import discover
>>> "leader" in discover()
True
"""
from nonholo.studies.base import SAMPLINGS, Study, StudyOptions, StudyResult, discover
from nonholo.studies.report import run_studies, write_report

__all__ = ["SAMPLINGS", "Study", "StudyOptions", "StudyResult", "discover", "run_studies", "write_report"]
