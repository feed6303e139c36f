"""Read GrowSpace recordings: summary, re-simulation check, GIF/MP4 export, republish, recovery.

``growspace-replay`` subcommands:
- ``info BAG``: episodes, returns, steps, duration, messages per topic;
- ``check BAG``: re-simulate every episode from the recorded config, seed and commands and
  report whether every image, plant state, applied light and reward is bit-identical (exit 0)
  or the first mismatch, or the episodes an unreadable part of the file kept from being
  checked (exit 1);
- ``export BAG OUT.gif|OUT.mp4``: one episode's camera images, with a progress bar;
- ``play BAG``: republish the messages on their topics over rclpy, with the recorded timing or
  as fast as possible (``ros2 bag play`` where rosbag2 is not installed); with
  ``--step-period``, step by step onto a lockstep node such as the LED gantry: each episode's
  reset first, each command once the previous step was answered;
- ``compare A B``: the applied light of B against A, matched by episode and step_id, max and
  RMS per field (a simulated run and the same commands replayed onto the LED gantry);
- ``recover BAG OUT``: copy every readable chunk of a file cut short by a crash or damaged,
  and say what was skipped; ``recover DIR`` repairs a split recording's last file in place.

BAG is a ``.mcap`` file or a split recording's directory (``recording.SplitRecorder``): its files
read as one.

An unreadable chunk never stops a reader: it is skipped and named (``Bag.damage``).

Messages are read in file order, which is the order the node handled them in (the topics and
their order are ``ros.interface``; the episode structure is in ``docs/recording.md``).

Modules, one job each: ``bag`` (reading), ``episodes`` (episode structure, summary), ``resim``
(bit-for-bit re-simulation), ``export`` (GIF/MP4), ``play`` (republishing over rclpy),
``compare`` (two runs' applied light) and ``cli`` (``growspace-replay``, also ``python -m
growspace_sim.replay``).
"""

from growspace_sim.replay.bag import Bag, BagMessage, ReplayError, TopicInfo
from growspace_sim.replay.cli import main
from growspace_sim.replay.compare import compare, Comparison, format_comparison
from growspace_sim.replay.episodes import (
    Episode, StepRecord, format_summary, read_episodes, summary)
from growspace_sim.replay.export import export_episode
from growspace_sim.replay.play import play, play_steps, StepReplay
from growspace_sim.replay.resim import (
    COMPARED, Mismatch, ResimReport, resimulate, resume_point, ResumePoint)

__all__ = ['Bag', 'BagMessage', 'COMPARED', 'Comparison', 'Episode', 'Mismatch', 'ReplayError',
           'ResimReport', 'ResumePoint', 'StepRecord', 'StepReplay', 'TopicInfo', 'compare',
           'export_episode', 'format_comparison', 'format_summary', 'main', 'play',
           'play_steps', 'read_episodes', 'resimulate', 'resume_point', 'summary']
