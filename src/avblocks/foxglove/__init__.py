"""Runs and flights as MCAP files for Foxglove (the ``foxglove`` extra).

    res.to_mcap("run.mcap")                                  # a simulated run
    avblocks export avblocks-out/drone_formation --mcap      # a run's folder
    write_flight(res, "flight-log.jsonl", "flight.mcap")     # a drone flight

:func:`write_results` writes Foxglove's well-known schemas (frame
transforms, 3-D scene entities, logs; protobuf) and the logged signals as
JSON messages with their JSON schemas, into an MCAP file written with the
``foxglove-sdk`` package; :func:`read_flight_log` reads the JSON-lines
flight log of ``--robots mavlink|crazyflies`` within limits;
:func:`case_study_layout` is the layout shipped in ``layouts/``. Importing
this package registers it as the ``"mcap"`` writer of
:meth:`avblocks.Results.to_mcap` (:mod:`avblocks.core.writers`). See
docs/foxglove.md.
"""

from ..core.writers import register_writer
from . import writer as _writer
from .flightlog import FlightLog, read_flight_log
from .layout import LAYOUT_FILE, case_study_layout, layout_json
from .writer import display_names, pose_sources, write_flight, write_results

register_writer("mcap", _writer)

__all__ = ["write_results", "write_flight", "read_flight_log", "FlightLog",
           "case_study_layout", "layout_json", "LAYOUT_FILE", "pose_sources",
           "display_names"]
