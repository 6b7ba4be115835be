"""tactbench-example: the hook module. Keep it light; the encoder loads on use."""

from tactbench import hookimpl


@hookimpl
def register_encoders(register):
    register(
        "contact-events",
        "tactbench_example.encoder:ContactEvents",
        summary="pressure + contact mask + contact onset/release events, 3 channels",
        requires=("numpy",),
    )
