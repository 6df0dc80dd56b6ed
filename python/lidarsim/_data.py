"""Data sets from the Rust side as ``xarray.Dataset`` objects.

The Rust side hands over what a NetCDF product of lidarsim holds (``run.nc``, ``profiles.nc``,
``summary.nc``, ``sensitivities.nc``) as plain parts: dimensions, variables (numpy arrays
that own the Rust buffers, or lists of text) and attributes. They are decoded here the way
``xarray.open_dataset`` decodes the file (CF conventions): a missing value is NaN with
``_FillValue`` in the variable's encoding, text variables are strings on their own
dimensions, and the variables a ``coordinates`` attribute names are coordinates. So
``lidarsim.run(scene)`` and ``xarray.open_dataset("out/run.nc")`` of the same run are
identical but for the ``history`` attribute.
"""

import numpy as np
import xarray as xr


def to_xarray(parts):
    """Build the ``xarray.Dataset`` of the parts ``(dims, variables, attributes)``."""
    dims, variables, attributes = parts
    sizes = dict(dims)
    data_vars = {}
    coord_names = set()
    encodings = {}
    for name, var_dims, values, attrs in variables:
        attrs = dict(attrs)
        encoding = {}
        if isinstance(values, list):
            # Text: a char array (…, strlen) in the file; a string per element here.
            var_dims = tuple(var_dims[:-1])
            shape = tuple(sizes[d] for d in var_dims)
            values = np.array(values, dtype=object).reshape(shape)
            attrs.pop("_Encoding", None)
        else:
            var_dims = tuple(var_dims)
            # A view of the Rust buffer, not a copy.
            values = values.reshape(tuple(sizes[d] for d in var_dims))
            if "_FillValue" in attrs:
                encoding["_FillValue"] = attrs.pop("_FillValue")
        if "coordinates" in attrs:
            coord_names.update(attrs["coordinates"].split())
            encoding["coordinates"] = attrs.pop("coordinates")
        data_vars[name] = xr.Variable(var_dims, values, attrs)
        encodings[name] = encoding
    # A variable named as its dimension is that dimension's coordinate (NetCDF convention).
    coords = {
        n: v for n, v in data_vars.items() if n in coord_names or (v.dims == (n,))
    }
    others = {n: v for n, v in data_vars.items() if n not in coords}
    ds = xr.Dataset(others, coords=coords, attrs=dict(attributes))
    for name, encoding in encodings.items():
        ds[name].encoding.update(encoding)
    return ds
