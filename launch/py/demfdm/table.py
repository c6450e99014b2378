"""Columns of a CSV file as numpy arrays, under their raw names and friendly names.

The run's CSV files name their columns `<role>.<quantity>_<unit>` (stage histories:
"dem.footing_fz_N", "continuum.time_s", "step") or `<quantity>_<unit>` (node histories and
profiles: "footing_disp_m", "szz_Pa", "balls_1", "step_unit"). A Table keeps every raw name and
adds, for the same arrays:
  * the name without its unit suffix, with its role: "dem.footing_fz";
  * the name without role and unit: "footing_fz". When two roles share it ("dem.time_s" and
    "continuum.time_s"), it names the column without a role first, then the DEM's, then the
    continuum's, then the others in file order (so "time" is the DEM's time; the raw and the
    "continuum.time" names stay);
  * the aliases "load" (footing load [N], compression positive) and "settlement" (footing
    displacement [m], downward positive): the DEM footing's columns, or the FDM punch's when the
    run has no DEM footing.
Units (`Table.units[name]`, "1" for dimensionless) come from the suffix; a name whose last part
is not a known unit ("dem.bond_failures", "continuum.ratio") has unit "" and keeps its name.
"""
import csv
import importlib.util

import numpy as np

# pandas is optional (Debian: python3-pandas); everything but Table.to_pandas works without it.
HAVE_PANDAS = importlib.util.find_spec("pandas") is not None

# Unit suffixes of the CsvSeries convention, longest first so "rho_b_kg_m3" -> ("rho_b", "kg_m3").
UNITS = ("kg_m3", "rad_s", "m_s2", "N_m", "m_s", "Pa", "kg", "m2", "m3", "Hz", "rad", "unit", "N", "m", "s",
         "J", "W", "1")
ROLE_ORDER = ("", "dem", "continuum")
ALIASES = {
    "load": ("dem.footing_fz_N", "footing_fz_N", "continuum.punch_fz_N", "punch_fz_N"),
    "settlement": ("dem.footing_disp_m", "footing_disp_m", "continuum.punch_disp_m", "punch_disp_m"),
}


def split_name(raw):
    """(role, stem, unit) of a raw column name: "dem.footing_fz_N" -> ("dem", "footing_fz", "N");
    "step_unit" -> ("", "step", "1"); "dem.bond_failures" -> ("dem", "bond_failures", "")."""
    role, _, rest = raw.rpartition(".") if "." in raw else ("", "", raw)
    for u in UNITS:
        if rest.endswith("_" + u) and len(rest) > len(u) + 1:
            return role, rest[: -len(u) - 1], "1" if u == "unit" else u
    return role, rest, ""


def friendly_name(raw):
    """The name without role and unit: "dem.footing_fz_N" -> "footing_fz"."""
    return split_name(raw)[1]


class Table(dict):
    """Columns as numpy arrays (float64, or str for a non-numeric column), one row per line.

    table[raw name], table[role.stem], table[stem], table["load"] and table["settlement"] all
    give the arrays (see the module doc). Attributes:
      columns   raw names in file order
      units     {every name: unit text}
      raw       {every name: its raw column name}
      rows      number of rows
      path      the file read (None when built in memory)
    """

    def __init__(self, columns, arrays, path=None):
        super().__init__()
        self.columns = list(columns)
        self.path = path
        self.units = {}
        self.raw = {}
        self.rows = len(arrays[0]) if arrays else 0
        for name, a in zip(self.columns, arrays):
            self._add(name, name, a)
        split = {n: split_name(n) for n in self.columns}
        for n, (role, stem, unit) in split.items():
            if role:
                self._add(role + "." + stem, n, self[n])
        def rank(n):
            role = split[n][0]
            return (ROLE_ORDER.index(role) if role in ROLE_ORDER else len(ROLE_ORDER), self.columns.index(n))
        for n in sorted(self.columns, key=rank):
            self._add(split[n][1], n, self[n])
        for alias, candidates in ALIASES.items():
            for c in candidates:
                if c in self.columns:
                    self._add(alias, c, self[c])
                    break

    def _add(self, name, raw, array):
        if name and name not in self:
            self[name] = array
            self.raw[name] = raw
            self.units[name] = split_name(raw)[2]

    def names(self):
        """Every name the table answers to (raw, role.stem, stem, aliases)."""
        return list(self.keys())

    def to_numpy(self):
        """The numeric columns as one float64 array [rows, columns] (raw column order) and their
        raw names."""
        names = [n for n in self.columns if self[n].dtype.kind == "f"]
        return np.column_stack([self[n] for n in names]) if names else np.empty((self.rows, 0)), names

    def to_pandas(self, friendly=False):
        """A pandas DataFrame of the columns in file order: raw names, or with friendly=True the
        shortest unique name of each column (its stem, else role.stem). Raises ImportError (naming
        the Debian package) when pandas is not installed."""
        try:
            import pandas as pd
        except ImportError as e:
            raise ImportError("Table.to_pandas needs pandas (apt-get install python3-pandas); "
                              "the Table itself is a dict of numpy arrays") from e
        if friendly:
            label = {}
            for name, raw in self.raw.items():
                if name not in ALIASES and raw not in label and name != raw and "." not in name:
                    label[raw] = name
            for name, raw in self.raw.items():
                if raw not in label and name != raw and name not in ALIASES:
                    label[raw] = name
            cols = [label.get(n, n) for n in self.columns]
        else:
            cols = list(self.columns)
        return pd.DataFrame({c: self[n] for c, n in zip(cols, self.columns)}, columns=cols)

    def __repr__(self):
        return "Table(%s, %d rows: %s)" % (self.path or "-", self.rows, ", ".join(self.columns))


def read_csv(path):
    """A CSV file with one header line (quoted fields allowed) as a Table. A column whose every
    value parses as a float becomes float64, any other a numpy str array; empty fields of a
    numeric column are NaN."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or not rows[0]:
        raise ValueError("%s: empty file, expected a header line" % path)
    header = [h.strip() for h in rows[0]]
    body = [r for r in rows[1:] if r and any(x.strip() for x in r)]
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise ValueError("%s: row %d has %d values, the header has %d columns" % (path, i + 2, len(r), len(header)))
    arrays = []
    for j in range(len(header)):
        vals = [r[j].strip() for r in body]
        try:
            arrays.append(np.array([float(v) if v else np.nan for v in vals], dtype=np.float64))
        except ValueError:
            arrays.append(np.array(vals, dtype=str))
    return Table(header, arrays, path=str(path))
