"""The CRS end of the CCSDS ground link: command reception, verification, acks and telemetry."""

from tlt_crs.ground_link.housekeeping import HousekeepingSchedule
from tlt_crs.ground_link.link import GroundCommand, GroundLink

__all__ = ["GroundCommand", "GroundLink", "HousekeepingSchedule"]
