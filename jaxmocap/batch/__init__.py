"""``jaxmocap batch``: many videos, each a Ray task that writes ``DIR/<stem>/`` as ``jaxmocap run`` would.

    from jaxmocap.batch import BatchConfig, batch
    from jaxmocap.pipeline import RunConfig
    report = batch(BatchConfig(("a.mp4", "b.mp4"), RunConfig("", overlay=False), workers=2), "out")

Modules: `config` (`BatchConfig`), `videos` (the inputs, a manifest's and each one's folder name), `ledger`
(``batch.json``/``batch.csv`` and the marks of finished videos), `task` (one video, in a Ray worker), `cluster`
(Ray started on 127.0.0.1 or joined at an address), `schedule` (`batch`: the tasks submitted, gathered, retried,
stopped on Ctrl-C). Ray is an optional extra (``pip install "jaxmocap[batch]"``); only `cluster` imports it.
"""

from jaxmocap.batch.config import BatchConfig
from jaxmocap.batch.ledger import VideoRecord
from jaxmocap.batch.schedule import BatchReport, batch
from jaxmocap.batch.videos import read_manifest

__all__ = ["BatchConfig", "BatchReport", "VideoRecord", "batch", "read_manifest"]
