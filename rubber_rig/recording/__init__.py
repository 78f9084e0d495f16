"""Recording: MCAP files in the ros2 profile that ros2 bag, Foxglove and rosbags read (ROS-free core).

- :class:`RecordingWriter` writes one file; :class:`Recorder` adds splitting, start/stop, snapshots
  and loss accounting on top (the recorder node only wires ROS to it).
- :func:`load_recording` turns recordings (ours or `ros2 bag record`'s) into numpy arrays.
- :func:`recover` rebuilds a file whose writer was killed.
"""
from .errors import RecordingError, RecordingWriteError
from .gaps import GapTracker
from .msgdefs import full_definition, normalize_type, register_definition, type_hash
from .qos import offered_qos_yaml, qos_entry
from .writer import CLOSE_METADATA_NAME, METADATA_NAME, RecordingWriter
from .reader import SIGNALS, Recording, load_recording
from .session import Recorder
from .recover import RecoverResult, recover
