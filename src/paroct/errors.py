"""The one exception type for user mistakes: bad input, bad options, impossible requests.

The CLI prints its message as one line and exits non-zero; library callers catch it.
Anything else escaping paroct is a bug in paroct.
"""


class ParoctError(Exception):
    """A problem with the input or the options, stated in one line with the numbers involved."""
