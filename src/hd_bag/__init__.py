"""The bag contract (``../shared/CONTRACT.md``): read, write, validate, replay and import actuator bags.

Public surface::

    from hd_bag import Mission, MissionMeta, ReadReport          # in-memory form
    from hd_bag import read_mission, write_mission, MissionWriter
    from hd_bag import validate_bag, Violation, BagError, iter_messages
    from hd_bag import read_metadata                               # metadata records without decoding chunks
    from hd_bag import import_csv                                  # CSV log -> contract bag
"""

from .errors import BagError, Violation
from .mission import Mission, MissionMeta, ReadReport
from .reader import bag_summary, iter_messages, read_mission, validate_bag
from .mcapio import read_metadata
from .writer import MissionWriter, write_mission


def import_csv(*args, **kwargs):
    """See :func:`hd_bag.csv_import.import_csv`."""
    from .csv_import import import_csv as _f

    return _f(*args, **kwargs)


__all__ = ["BagError", "Violation", "Mission", "MissionMeta", "ReadReport", "read_mission", "write_mission",
           "MissionWriter", "validate_bag", "iter_messages", "bag_summary", "import_csv", "read_metadata"]
