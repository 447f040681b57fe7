"""Scale-out: run biomorph work over many inputs on dask.distributed (``biomorph[scale]``).

See :func:`biomorph.scale.batch.run_batch` and ``docs/gltf_and_batch.md``.
"""

from biomorph.scale.batch import BatchReport, run_batch

__all__ = ["BatchReport", "run_batch"]
