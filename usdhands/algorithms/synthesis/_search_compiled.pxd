# The search module's C-level functions other compiled modules of the package call.
from libc.stdint cimport int64_t

cdef double _align_path(const double[:, ::1] q, const double[:, ::1] d, double band, int64_t[::1] path) except? -1.0
