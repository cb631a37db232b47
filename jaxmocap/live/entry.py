"""`live`: the one entry of ``jaxmocap live`` for every ``--mode``; it starts the bodies' session
(`session.Session`: ``whole`` and ``body``) or the hands' (`hands.HandSession`). The sessions do not import this
module, and the hands' session builds on the bodies' one, never the other way."""

from jaxmocap.live.hands import HandSession
from jaxmocap.live.session import LiveConfig, LiveReport, Session


def live(config: LiveConfig, started=None) -> LiveReport:
    """Run a live session until the source ends, ``max_frames`` are solved or Ctrl-C; ``started(url)`` is called when
    capture starts, after compiling (``url``: where to watch the web page, its token included, or None). ``mode``
    ``hands`` solves hands alone (`HandSession`)."""
    session = HandSession(config) if config.mode == "hands" else Session(config)
    try:
        session.warm_up()
    except BaseException:
        session.close()
        raise
    if started is not None:
        started(None if session.viewer is None else session.viewer.url)
    return session.run()
