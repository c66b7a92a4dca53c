"""A run's data as files for analysis.

Its reward log and episodes (JSON Lines and CSV with the same rows), its learned network, a
manifest, and on request a Minari dataset (the `srlab[minari]` extra); a study's export is
its participants' runs under their pseudonyms with the study's tables. docs/export.md says
what each file holds.
"""

from server.export.archive import zip_folder
from server.export.dataset import MINARI_EXTRA, MinariMissingError, dataset_id
from server.export.run import SCHEMA_VERSION, RunExport, export_run
from server.export.study import StudyExport, export_study
from server.export.tables import EPISODE_COLUMNS, REWARD_COLUMNS, csv_cell

__all__ = [
    "EPISODE_COLUMNS",
    "MINARI_EXTRA",
    "REWARD_COLUMNS",
    "SCHEMA_VERSION",
    "MinariMissingError",
    "RunExport",
    "StudyExport",
    "csv_cell",
    "dataset_id",
    "export_run",
    "export_study",
    "zip_folder",
]
