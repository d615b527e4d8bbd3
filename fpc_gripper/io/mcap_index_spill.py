"""Chunk indexes of an MCAP file being written, kept in a file of their own, not in memory."""

import tempfile

from mcap.data_stream import RecordBuilder

__all__ = ['SpilledRecords', 'spill_chunk_indexes']

# The list in which mcap's Writer keeps a ChunkIndex per chunk until `finish` writes them
# into the summary (mcap 1.x: `Writer.__chunk_indices`, appended to and iterated once).
_WRITER_ATTRIBUTE = '_Writer__chunk_indices'


class _Raw:
    """Bytes of serialised records, written as they are into the summary."""

    __slots__ = ('data',)

    def __init__(self, data):
        self.data = data

    def write(self, builder):
        builder.write(self.data)


class SpilledRecords:
    """
    MCAP records kept serialised in an anonymous file, in order, until they are read once.

    mcap's Writer keeps one ChunkIndex object per chunk for the summary, about 1 kB each
    with nine channels: a recorder that closes a chunk at every flush (twice a second)
    and whenever it is full grew by tens of MiB an hour. Here each record costs its
    serialised bytes (77 + 10 per channel in the chunk) on disk and none in memory; the
    summary gets exactly the bytes the records would have written.

    Parameters
    ----------
    directory : str or os.PathLike
        Where the anonymous file lives (the recording's own directory: it has the room).

    """

    def __init__(self, directory):
        self._file = tempfile.TemporaryFile(dir=directory)
        self._builder = RecordBuilder()
        self._count = 0

    def append(self, record):
        """Serialise one record (anything with mcap's ``write(builder)``) to the file."""
        record.write(self._builder)
        self._file.write(self._builder.end())
        self._count += 1

    def __len__(self):
        return self._count

    def __iter__(self):
        """Yield the records' bytes, in pieces that write themselves into a RecordBuilder."""
        self._file.seek(0)
        while True:
            data = self._file.read(1 << 20)
            if not data:
                break
            yield _Raw(data)
        self._file.seek(0, 2)

    def close(self):
        """Remove the file (idempotent)."""
        self._file.close()


def spill_chunk_indexes(writer, directory):
    """
    Keep the chunk indexes of a new mcap `Writer` in a `SpilledRecords` file.

    Parameters
    ----------
    writer : mcap.writer.Writer
        A writer that has closed no chunk yet.
    directory : str or os.PathLike
        See `SpilledRecords`.

    Returns
    -------
    SpilledRecords or None
        None if the writer does not keep its chunk indexes as this mcap version does
        (they then stay in memory, as mcap keeps them).

    """
    if getattr(writer, _WRITER_ATTRIBUTE, None) != []:
        return None
    records = SpilledRecords(directory)
    setattr(writer, _WRITER_ATTRIBUTE, records)
    return records
