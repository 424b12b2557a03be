# course.sh - sourced by the test scripts: where the course scenes and their
# reference images are. Meson passes its default (../shared/scenes/course
# beside the checkout) in RAYBENCH_COURSE_DEFAULT; RAYBENCH_COURSE_DIR set by
# the user when running the tests wins. The reference images are read from
# the folder reference/ two levels above the scenes, as ../shared lays out.
#   course_path course:InterestingScenes/dragon.txt  -> DIR/InterestingScenes/dragon.txt
#   course_path reference:dragon.png                 -> DIR/../../reference/dragon.png
#   course_path course:                              -> DIR
#   anything else is printed as it is (the project's own scenes)
course_path() {
    _cdir=${RAYBENCH_COURSE_DIR:-${RAYBENCH_COURSE_DEFAULT:-../shared/scenes/course}}
    case $1 in
    course:*) printf '%s\n' "$_cdir/${1#course:}" ;;
    reference:*) printf '%s\n' "$_cdir/../../reference/${1#reference:}" ;;
    *) printf '%s\n' "$1" ;;
    esac
}
