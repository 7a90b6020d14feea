"""The one error type that user-facing commands turn into a one-line message."""


class HysidInputError(ValueError):
    """Bad input (a file, an argument or a message): the text names what is wrong.

    The message is a single line meant for the user, e.g.
    ``data/run1.csv: column 'force_n' missing (found: time_s, displacement_m, force)``.
    """

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))
