"""Imported by the local pool's forkserver that ``usdhands batch`` starts warm, before it forks a worker.

See :func:`usdhands.jobs.batch.start_warm_forkserver`: importing this module loads the
synthesize job's modules, the bundled database and numba into the importing process.
Nothing else imports it.
"""

from usdhands.jobs.batch import _warm_forkserver_process

_warm_forkserver_process()
