"""tactbench-icub: the hook module. Keep it light; the reader loads on use."""

from tactbench import hookimpl


@hookimpl
def register_datasets(register):
    register(
        "icub-grasp",
        "tactbench_icub.reader:ICubGrasp",
        summary="real iCub fingertips grasping 9 objects + none (Soh et al., IROS 2012); "
                "60 taxel vectors, joints=true adds 9 joints; path=FOLDER",
        requires=("numpy",),
    )
