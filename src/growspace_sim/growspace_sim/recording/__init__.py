"""Record chamber topics to MCAP the way rosbag2 does (profile ``ros2``), and recover broken files.

A recording is one bare ``.mcap`` file that Jazzy ``ros2 bag info/play``, Foxglove, ``rosbags``
and ``mcap_ros2`` read (the rosbag2 MCAP storage conventions, docs/recording.md):

- header profile ``ros2``; one ``ros2msg`` schema per type (the concatenated definition from
  ``ros.types.msgdef``); channels with ``message_encoding='cdr'`` and the metadata
  ``offered_qos_profiles`` (rosbag2 v9 YAML) and ``topic_type_hash`` (RIHS01);
- messages are the exact CDR bytes put on the wire, encapsulation header included;
- zstd chunks of at most ``chunk_size`` bytes, also closed every ``flush_period_s`` seconds, so a
  hard kill loses at most the open chunk: ``recover()`` copies every complete chunk of a file
  that has no summary into a fresh file;
- a metadata record ``growspace`` with the effective config, seed, software version and the
  chamber geometry (``growspace_metadata``).

The chamber's side of the contract (topics, ``chamber/config`` payload, the ``growspace``
metadata) lives in ``growspace_sim.ros.interface``; the names below re-export it because they
are part of the file format.

Example:
    with McapRecorder('run.mcap') as rec:
        ch = rec.add_channel('/growspace/step_result', types.STEP_RESULT, qos.DEFAULT)
        rec.write(ch, types.serialize(msg, types.STEP_RESULT), t_ns, t_ns)

A long run is split into files by size and duration (``SplitRecorder``, rosbag2's
``--max-bag-size`` / ``--max-bag-duration`` layout: ``NAME/NAME_0.mcap``, ``NAME_1.mcap``, ...,
``metadata.yaml``); ``replay.Bag`` reads such a directory as one recording.

Modules: ``recorder`` (``McapRecorder``, signals, exit), ``chunk_writer`` (the byte-level MCAP
writer), ``recovery`` (``recover``) and ``splits`` (``SplitRecorder``, ``repair``).
"""

from growspace_sim.recording.recorder import (
    CHUNK_SIZE, FLUSH_PERIOD_S, LIBRARY, McapRecorder, PROFILE, RecordingError, stop_on_signals)
from growspace_sim.recording.recovery import recover, RecoveryReport
from growspace_sim.recording.splits import (
    is_split_recording, repair, RepairReport, split_files, split_path, SplitRecorder,
    wait_until_free)
from growspace_sim.ros.interface import (  # noqa: F401 - re-exported: part of the file format
    FORMAT, METADATA_NAME, config_dict, config_json, digit_fingerprint, growspace_metadata)

__all__ = ['CHUNK_SIZE', 'FLUSH_PERIOD_S', 'FORMAT', 'LIBRARY', 'McapRecorder', 'METADATA_NAME',
           'PROFILE', 'RecordingError', 'RecoveryReport', 'config_dict', 'config_json',
           'RepairReport', 'SplitRecorder', 'digit_fingerprint', 'growspace_metadata',
           'is_split_recording', 'recover', 'repair', 'split_files', 'split_path',
           'stop_on_signals', 'wait_until_free']
