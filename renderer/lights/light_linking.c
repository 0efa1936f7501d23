/* renderer/lights/light_linking.c: light linking's link classes (lights.h, LightLinking).
 *
 * A light with a receivers list (extras.candela_light_linking.receivers, resolved by io/ to
 * instance lists) reaches an instance when the instance is in its include list, or not in its
 * exclude list. An instance's *membership* is the list of such lights whose list names it;
 * instances with the same membership are reached by the same lights: one link class. A vertex
 * in a medium has the empty membership. The classes are usually few (the distinct ways the
 * scene's links cut it up), which is what lets every strategy keep one distribution per class.
 * Class 0 is "every light": the class of every membership that excludes nothing, and of the
 * camera, so a scene whose links exclude nothing (blockers only) has one class. */
/* qsort_r: _GNU_SOURCE (the build defines it) */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lights.h"
#include "scene.h"

#define LINK_MAX_CLASSES 65535u /* PathState keeps the class in 16 bits */

typedef struct Membership {
    const uint32_t *off, *lights; /* CSR over pseudo-instances (the instances, then the medium) */
} Membership;

static int cmp_membership(const void *a, const void *b, void *vm) {
    const Membership *m = vm;
    uint32_t i = *(const uint32_t *)a, j = *(const uint32_t *)b;
    uint32_t ni = m->off[i + 1] - m->off[i], nj = m->off[j + 1] - m->off[j];
    if (ni != nj) return ni < nj ? -1 : 1;
    int c = memcmp(m->lights + m->off[i], m->lights + m->off[j], ni * sizeof(uint32_t));
    if (c) return c;
    return i < j ? -1 : (i > j); /* stable: a total order */
}

static int same_membership(const Membership *m, uint32_t i, uint32_t j) {
    uint32_t ni = m->off[i + 1] - m->off[i];
    return ni == m->off[j + 1] - m->off[j] && !memcmp(m->lights + m->off[i], m->lights + m->off[j], ni * sizeof(uint32_t));
}

void lights_free_linking(Lights *ls) {
    LightLinking *k = ls->link;
    if (!k) return;
    free(k->class_of_instance);
    free(k->enabled);
    free(k->enabled_off);
    free(k->enabled_lights);
    free(k->disabled_off);
    free(k->disabled_lights);
    free(k->exclusive_off);
    free(k->exclusive_lights);
    free(k->shadow_mask);
    free(k);
    ls->link = NULL;
}

int lights_build_linking(Lights *ls, const Scene *scene, char *err, size_t err_len) {
    const IoScene *io = &scene->io;
    if (!io->num_light_links) return 0;
    uint32_t n = ls->count, ni = io->num_instances;
    int receivers = 0;
    for (uint32_t l = 0; l < n; ++l)
        if (ls->lights[l].link >= 0 && io->light_links[ls->lights[l].link].receivers != IO_LINK_ALL) receivers = 1;
    if (!receivers && !scene->link_shadow_mask) return 0; /* links on nodes without lights */
    LightLinking *k = calloc(1, sizeof *k);
    uint32_t *off = calloc((size_t)ni + 3, sizeof *off), *members = NULL, *order = NULL, *group = NULL;
    ls->link = k;
    if (!k || !off) goto oom;
    k->class_of_instance = calloc((size_t)ni + 1, sizeof *k->class_of_instance);
    if (!k->class_of_instance) goto oom;
    if (scene->link_shadow_mask) {
        k->shadow_mask = malloc(((size_t)n + 1) * sizeof *k->shadow_mask);
        if (!k->shadow_mask) goto oom;
        for (uint32_t l = 0; l < n; ++l)
            k->shadow_mask[l] = ls->lights[l].link >= 0 ? scene->link_shadow_mask[ls->lights[l].link] : SCENE_MASK_SURFACES;
    }
    /* memberships (pseudo-instance ni: a medium vertex, member of nothing), lights ascending */
    for (uint32_t l = 0; l < n; ++l) {
        const Light *L = &ls->lights[l];
        if (L->link < 0 || io->light_links[L->link].receivers == IO_LINK_ALL) continue;
        const IoLightLink *lk = &io->light_links[L->link];
        for (uint32_t j = 0; j < lk->num_receivers; ++j) off[io->link_instances[lk->first_receiver + j] + 1]++;
    }
    for (uint32_t i = 0; i < ni + 1; ++i) off[i + 1] += off[i];
    members = malloc(((size_t)off[ni + 1] + 1) * sizeof *members);
    uint32_t *fill = calloc((size_t)ni + 1, sizeof *fill);
    if (!members || !fill) { free(fill); goto oom; }
    for (uint32_t l = 0; l < n; ++l) {
        const Light *L = &ls->lights[l];
        if (L->link < 0 || io->light_links[L->link].receivers == IO_LINK_ALL) continue;
        const IoLightLink *lk = &io->light_links[L->link];
        for (uint32_t j = 0; j < lk->num_receivers; ++j) {
            uint32_t i = io->link_instances[lk->first_receiver + j];
            members[off[i] + fill[i]++] = l;
        }
    }
    free(fill);
    Membership m = {off, members};
    order = malloc(((size_t)ni + 1) * sizeof *order);
    group = malloc(((size_t)ni + 1) * sizeof *group);
    if (!order || !group) goto oom;
    for (uint32_t i = 0; i <= ni; ++i) order[i] = i;
    qsort_r(order, (size_t)ni + 1, sizeof *order, cmp_membership, &m);
    /* the distinct memberships, each a candidate class (class 0 when it excludes nothing) */
    uint32_t groups = 0;
    for (uint32_t s = 0; s <= ni; ++s) {
        if (s == 0 || !same_membership(&m, order[s], order[s - 1])) groups++;
        group[order[s]] = groups - 1;
    }
    uint8_t *row = malloc((size_t)n + 1);
    uint32_t *class_of_group = malloc((size_t)groups * sizeof *class_of_group);
    k->enabled = malloc(((size_t)groups + 1) * n + 1);
    if (!row || !class_of_group || !k->enabled) { free(row); free(class_of_group); goto oom; }
    memset(k->enabled, 1, n); /* class 0 */
    k->num_classes = 1;
    for (uint32_t s = 0, g = UINT32_MAX; s <= ni; ++s) {
        uint32_t i = order[s];
        if (group[i] == g) continue;
        g = group[i];
        int all = 1;
        for (uint32_t l = 0; l < n; ++l) { /* the lights that reach the membership */
            const Light *L = &ls->lights[l];
            int mode = L->link >= 0 ? io->light_links[L->link].receivers : IO_LINK_ALL;
            if (mode == IO_LINK_ALL) { row[l] = 1; continue; }
            int member = 0;
            for (uint32_t j = off[i]; j < off[i + 1] && !member; ++j) member = members[j] == l;
            row[l] = (uint8_t)(mode == IO_LINK_INCLUDE ? member : !member);
            all &= row[l];
        }
        if (all) { class_of_group[g] = 0; continue; }
        if (k->num_classes == LINK_MAX_CLASSES) {
            free(row); free(class_of_group);
            snprintf(err, err_len, "%.400s: light linking makes more than %u classes of objects", io->path,
                     LINK_MAX_CLASSES);
            lights_free_linking(ls);
            free(off); free(members); free(order); free(group);
            return -1;
        }
        memcpy(k->enabled + (size_t)k->num_classes * n, row, n);
        class_of_group[g] = k->num_classes++;
    }
    for (uint32_t i = 0; i < ni; ++i) k->class_of_instance[i] = (uint16_t)class_of_group[group[i]];
    k->media_class = (uint16_t)class_of_group[group[ni]];
    free(row);
    free(class_of_group);
    /* per class: its lights and the others, ascending (uniform picks, cache points' far lists) */
    uint32_t C = k->num_classes;
    k->enabled_off = calloc((size_t)C + 1, sizeof(uint32_t));
    k->disabled_off = calloc((size_t)C + 1, sizeof(uint32_t));
    size_t on = 0;
    for (size_t x = 0; x < (size_t)C * n; ++x) on += k->enabled[x];
    k->enabled_lights = malloc((on + 1) * sizeof(uint32_t));
    k->disabled_lights = malloc(((size_t)C * n - on + 1) * sizeof(uint32_t));
    if (!k->enabled_off || !k->disabled_off || !k->enabled_lights || !k->disabled_lights) goto oom;
    uint32_t e = 0, d = 0;
    for (uint32_t c = 0; c < C; ++c) {
        k->enabled_off[c] = e;
        k->disabled_off[c] = d;
        for (uint32_t l = 0; l < n; ++l) {
            if (k->enabled[(size_t)c * n + l]) k->enabled_lights[e++] = l;
            else k->disabled_lights[d++] = l;
        }
    }
    k->enabled_off[C] = e;
    k->disabled_off[C] = d;
    /* the exclusive lights: enabled ones whose receivers list is an include list */
    k->exclusive_off = calloc((size_t)C + 1, sizeof(uint32_t));
    k->exclusive_lights = malloc(((size_t)e + 1) * sizeof(uint32_t));
    if (!k->exclusive_off || !k->exclusive_lights) goto oom;
    uint32_t x = 0;
    for (uint32_t c = 0; c < C; ++c) {
        k->exclusive_off[c] = x;
        for (uint32_t j = k->enabled_off[c]; j < k->enabled_off[c + 1] && c > 0; ++j) {
            const Light *L = &ls->lights[k->enabled_lights[j]];
            if (L->link >= 0 && io->light_links[L->link].receivers == IO_LINK_INCLUDE) k->exclusive_lights[x++] = k->enabled_lights[j];
        }
    }
    k->exclusive_off[C] = x;
    free(off); free(members); free(order); free(group);
    return 0;
oom:
    free(off); free(members); free(order); free(group);
    lights_free_linking(ls);
    snprintf(err, err_len, "out of memory while building light linking");
    return -1;
}
