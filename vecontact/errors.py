"""User-facing errors: one line, exit status 2, nothing written."""


class InputError(Exception):
    """Bad job file, bad command-line argument or unusable input file.

    The message is one line naming the key (dotted path, e.g. ``surface.q1``) and the problem.
    """

    def __init__(self, key, problem):
        self.key = key
        self.problem = problem
        super().__init__(f"{key}: {problem}" if key else problem)


class ResultsFileError(InputError):
    """A results file that cannot be reused (foreign job, corrupted, changed physics)."""


class InputWarning(UserWarning):
    """An input that works but deserves a look (e.g. a master curve that does not cover the
    frequencies the job needs: it is extrapolated). The command line prints it as one line."""
