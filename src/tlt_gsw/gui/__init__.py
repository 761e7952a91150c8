"""The GSW Qt GUI (paper §V.A, Fig. 6): every display is a query on the telemetry archive.

``app``            ``tlt gsw gui`` entry point (live or replay, screenshots)
``main_window``    the window and its refresh loop
``archive_model``  incremental and seek queries on the archive; the state every view shows
``link_process``   the link in its own process (so drawing never delays reception)
``link_worker``    the link thread it runs: receives into the archive, sends queued commands
``qt_check``       refuses a Qt binding that would crash the interpreter (PySide6 6.12 on 3.11)
``config``         ``config/gsw/gui.yaml``; ``tree_definitions``: optional files of tree shapes
views: ``link_status``, ``command_panel``, ``command_history``, ``housekeeping``, ``plots``,
``tree_view``, ``tower_view`` (+ ``tower_layout``), ``event_log``, ``packet_view``, ``replay_bar``
``demo_archive``   a mission-in-progress archive of real packets (docs, tests)
"""
