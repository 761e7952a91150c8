"""Recording the run's ROS traffic to MCAP (``tlt-record``), and reading it back.

``cli``: the ``tlt-record`` command. ``recorder``: the node that finds topics and subscribes raw.
``mcap_writer``: the file side. ``message_definitions``: ``ros2msg`` schema texts from installed
interface files. ``message_types``: message classes from type names. ``qos_profiles``: the QoS to
subscribe with and to store. ``header_stamp``: a message's stamp from its CDR bytes.
``topic_filter``: which topics are taken. ``reading``: decoded messages of a recording.
``recovery``: the messages of a recording cut short by a crash (``tlt-mcap-recover``).
``record_command``: the ``tlt record`` command over ``summary`` (topics, counts, times, rates),
``player`` (the recorded messages published again at their timing, with ``/clock``) and
``csv_export`` (chosen topics as CSV). See docs/recording.md.
"""
