"""Print the latest TensorBoard scalars of a training run: python tools/tb_tail.py RUN_DIR."""
import glob
import sys

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

run = sys.argv[1]
for path in sorted(glob.glob(f"{run}/tb/*")):
    acc = EventAccumulator(path)
    acc.Reload()
    for tag in sorted(acc.Tags()["scalars"]):
        values = acc.Scalars(tag)
        print(f"{tag:32s}", " ".join(f"{v.step}:{v.value:.3g}" for v in values[-5:]))
